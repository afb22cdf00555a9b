"""The study layer, shared by the command line and the job service.

- :mod:`.presets`: the paper's 23 roads with its optimum on each; resolving road lists.
- :mod:`.sweep`: Table 9 and user design grids.
- :mod:`.space`: the Table 8 search box and the Table 10 DE parameters.
- :mod:`.scoring`: the rule for a failed evaluation; scores over several roads.
- :mod:`.sharpness`: how sharp an optimum is (near-optimal set, sensitivities).
- :mod:`.runs`: sweeps and DEs as runs that hand out independent simulations.
- :mod:`.plan`: a study resolved from user input.

See docs/optimisation.md.
"""
