"""Turning job specs into work, and running it through the workers executor."""
