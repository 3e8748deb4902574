"""Plots for identified models and data. matplotlib is imported lazily.

Install the ``plot`` extra (``pip install ".[plot]"`` in the source folder).
Every function returns a :class:`matplotlib.figure.Figure` and never shows or
saves it: the caller
decides (``fig.savefig(...)``, or display in a notebook). Without a display
(no ``DISPLAY`` on Linux) the ``Agg`` backend is selected.

=====================================  ==========================================
:func:`data_overview`                  inputs and outputs against time
:func:`compare`                        measured against simulated outputs, fit %
:func:`bode`                           magnitude and phase, bands, measured data
:func:`step`                           step responses (with confidence bands)
:func:`poles`                          pole map with unit circle / imaginary axis
:func:`residuals`                      residual whiteness and input correlation
:func:`convergence`                    poles and parameters of an online run
:func:`order_selection`                singular values / rank profile, chosen order
:func:`error_histograms`               Monte-Carlo error distributions
=====================================  ==========================================

Every figure is drawn at 150 dpi with 10 pt text (:data:`STYLE`); a method has
the same colour in every figure (:data:`METHOD_COLORS`, by
``model.info['method']``); legends sit beside the axes, never over the data;
unstable models are dashed and marked "(unstable)" in the Bode diagram.

>>> import subid
>>> data = subid.datasets.load("dryer").detrend()          # doctest: +SKIP
>>> est, val = data.split(0.7)                              # doctest: +SKIP
>>> model = subid.moesp(est)                                # doctest: +SKIP
>>> subid.plot.compare(val, {"moesp": model})               # doctest: +SKIP
>>> subid.plot.bode(model, hz=True)                         # doctest: +SKIP
"""

from __future__ import annotations

# The figures live in subid.evaluation.figures, one module per family (issue 24); this
# module is their one public name (with subid.plot).
from subid.evaluation.figures._common import MAX_TRACE_POINTS as MAX_TRACE_POINTS
from subid.evaluation.figures._common import METHOD_COLORS as METHOD_COLORS
from subid.evaluation.figures._common import STYLE as STYLE
from subid.evaluation.figures._common import _min_max_blocks, _pyplot  # noqa: F401  (tests)
from subid.evaluation.figures._common import colors_for as colors_for
from subid.evaluation.figures._common import is_unstable as is_unstable
from subid.evaluation.figures._common import predicted_output as predicted_output
from subid.evaluation.figures._common import simulated_output as simulated_output
from subid.evaluation.figures.online import convergence as convergence
from subid.evaluation.figures.orders import order_scores as order_scores
from subid.evaluation.figures.orders import order_selection as order_selection
from subid.evaluation.figures.poles import error_histograms as error_histograms
from subid.evaluation.figures.poles import poles as poles
from subid.evaluation.figures.residuals import residual_correlations as residual_correlations
from subid.evaluation.figures.residuals import residuals as residuals
from subid.evaluation.figures.responses import bode as bode
from subid.evaluation.figures.responses import frequency_grid as frequency_grid
from subid.evaluation.figures.responses import step as step
from subid.evaluation.figures.time_domain import compare as compare
from subid.evaluation.figures.time_domain import data_overview as data_overview

# (order_scores, predicted_output, colors_for and is_unstable, public names of this module
# when it held the figures, are listed too: the API reference documents __all__.)
__all__ = ["poles", "error_histograms", "bode", "step", "compare", "residuals",
           "residual_correlations", "convergence", "data_overview", "frequency_grid",
           "simulated_output", "order_selection", "STYLE", "METHOD_COLORS",
           "order_scores", "predicted_output", "colors_for", "is_unstable"]
