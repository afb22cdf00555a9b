"""finaldrive's user-facing layer: the REST job service and the command line.

Importing this package is cheap: the web stack is imported only by the modules that serve.
"""
