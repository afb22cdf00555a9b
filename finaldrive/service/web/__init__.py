"""The dashboard served by ``finaldrive serve`` at /: jobs, job and design pages, offline API docs and
rerun's web viewer."""

from finaldrive.service.web.pages import install, login_page

__all__ = ["install", "login_page"]
