"""Online identifiers: recursive subspace (seed 001) and the adaptive continuous-time identifier (seed 000)."""
