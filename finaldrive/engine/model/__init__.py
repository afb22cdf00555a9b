"""The model description: coordinates, parameters, constraints, masses, forces, tyre, road."""
