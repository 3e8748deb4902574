"""Reproductions of the papers' experiments, runnable as commands.

``python -m subid.experiments.seed001`` — seed 001, Section IV.
"""
