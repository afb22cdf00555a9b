"""HTTP layer of the job service: routes, dependencies, error rendering."""
