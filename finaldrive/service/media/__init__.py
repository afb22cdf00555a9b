"""Pictures of designs: rerun recordings of them riding a road (``recording``, drawn from ``scene``'s
frames) and PNG figures (``plots``: sweep maps, DE histories, Fig. 13's series). The only place rerun is
imported (``recording``); used by the command line, the service's recordings and the report.
"""
