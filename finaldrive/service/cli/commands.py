"""Every command's name, the module that registers it and its one-line help: ``finaldrive --help`` lists
them without importing the modules (numpy, pydantic and the service's settings take ~0.3 s), and each
module's ``register`` reads its commands' help here.
"""

from __future__ import annotations

from typing import NamedTuple


class Command(NamedTuple):
    module: str  # in finaldrive.service.cli
    help: str


#: In the order ``--help`` lists them.
COMMANDS: dict[str, Command] = {
    'geometry': Command('engine_cmds', "a design's static quantities (squat ratio, chain length), no simulation"),
    'simulate': Command('engine_cmds', 'simulate one design on one road, in this process'),
    'evaluate': Command('engine_cmds', 'simulate a CSV of designs (a2_deg,l2_m,rws_m) in this process'),
    'model-band': Command('engine_cmds', 'a CSV of designs under the documented modelling alternatives (tyre load '
                                         'range, drive level and the launch drive, road phase): does their ranking '
                                         'survive them?'),
    'calibrate': Command('engine_cmds', 'solve the chassis centre of mass and the drive torque of a vehicle file'),
    'optimize': Command('study_cmds', "the paper's DE on one road, or one DE over several roads (local)"),
    'sweep': Command('study_cmds', 'simulate a design grid (Table 9 by default) on one or more roads (local)'),
    'roads': Command('roads_cmds', "the paper's 23 road presets with its optimum on each"),
    'serve': Command('server_cmds', 'run the REST job service and a scheduler beside it'),
    'scheduler': Command('server_cmds', 'run a scheduler: claims jobs from the database and runs their simulations'),
    'db': Command('server_cmds', 'manage the results database'),
    'submit': Command('jobs_cmds', 'submit a sweep, de or robust-de job to the service'),
    'jobs': Command('jobs_cmds', "list the service's jobs, newest first"),
    'status': Command('jobs_cmds', "a job's progress; --follow draws a progress bar until it ends"),
    'results': Command('jobs_cmds', "a job's evaluations as CSV (stdout, or --csv FILE)"),
    'best': Command('jobs_cmds', "a job's best design on each road, and which variables it decides"),
    'cancel': Command('jobs_cmds', 'cancel a job (a finished job is left as it is)'),
    'record': Command('media_cmds', 'a rerun .rrd of designs side by side on a road (local, or --job-id/--server)'),
    'plot': Command('media_cmds', "PNG: a job's sweep map or DE history (service), or Fig. 13 series (local)"),
    'study': Command('paper_cmds', 'run a study'),
    'report': Command('paper_cmds', 'write a report from stored results'),
    'demo': Command('demo_cmds', 'start a local service, run a small DE through it, print the best design, stop'),
}
