"""Evaluation: validation metrics, prediction and residuals, plots and the HTML report."""
