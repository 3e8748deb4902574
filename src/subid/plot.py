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
    compare,
    convergence,
    data_overview,
    error_histograms,
    frequency_grid,
    order_selection,
    poles,
    residual_correlations,
    residuals,
    simulated_output,
    step,
)

__all__ = ["poles", "error_histograms", "bode", "step", "compare", "residuals",
           "residual_correlations", "convergence", "data_overview", "frequency_grid",
           "simulated_output", "order_selection", "STYLE", "METHOD_COLORS"]
