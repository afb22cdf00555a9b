"""The fast path: minimal coordinates and a linearly implicit Rosenbrock-W step (issue 3)."""
