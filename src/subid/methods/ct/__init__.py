"""Continuous-time identification with orthonormal basis filters (seed 002) and the discrete-to-continuous baseline."""
