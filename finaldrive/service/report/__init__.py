"""Reports generated from stored studies (markdown + JSON + PNG figures); see :func:`write_paper_study`."""

from finaldrive.service.report.build import ReportFiles, build_paper_study, write_paper_study

__all__ = ["ReportFiles", "build_paper_study", "write_paper_study"]
