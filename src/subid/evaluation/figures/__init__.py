"""The figures of :mod:`subid.evaluation.plot`, one module per family (issue 24)."""
