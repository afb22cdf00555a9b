"""finaldrive: the best motorcycle final-drive geometry, by simulating the whole motorcycle on uneven roads.

Its subpackages: :mod:`finaldrive.engine` (the model, the solvers and the optimisers; its facade is the
engine's one interface), :mod:`finaldrive.workers` (where simulations run: in-process, a process pool or
Ray), :mod:`finaldrive.service` (the REST job service, the results store, the command line, reports and
recordings) and :mod:`finaldrive.migrations` (the store's schema). Importing this package imports none
of them.
"""
