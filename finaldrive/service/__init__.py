"""finaldrive's user-facing layer: the REST job service and the command line.

Importing this package is cheap: the web stack is imported only by the modules that serve.
"""

if __name__ != "finaldrive.service":  # never importable as a top-level `service` (it would shadow others)
    raise ImportError(f"this is finaldrive.service; import it by that name, not as {__name__!r}")
