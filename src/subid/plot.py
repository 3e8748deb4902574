"""Figures of identified models and data: ``import subid.plot``.

The public name of :mod:`subid.evaluation.plot`, where the functions are
implemented and documented; ``subid.plot.bode``, ``from subid.plot import
bode`` and ``import subid.plot`` all give the same functions. matplotlib is
imported when a figure is drawn, not by this import.
"""

from subid.evaluation.plot import (
    METHOD_COLORS,
    STYLE,
    bode,
    colors_for,
    compare,
    convergence,
    data_overview,
    error_histograms,
    frequency_grid,
    is_unstable,
    order_scores,
    order_selection,
    poles,
    predicted_output,
    residual_correlations,
    residuals,
    simulated_output,
    step,
)

__all__ = ["poles", "error_histograms", "bode", "step", "compare", "residuals",
           "residual_correlations", "convergence", "data_overview", "frequency_grid",
           "simulated_output", "order_selection", "STYLE", "METHOD_COLORS",
           "order_scores", "predicted_output", "colors_for", "is_unstable"]
