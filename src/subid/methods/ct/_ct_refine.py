"""The output-error refinement of a :func:`subid.ct_subspace` model: Levenberg-Marquardt on
(A, C) (:func:`subid.methods.ct._ct_fit.refine_output_error`), optionally prewhitened by an
AR noise model of the output error, then B, D, x0 and the offsets of the refined (A, C) by
the ``'simulation'`` route of :func:`subid.methods.bd.fit_b_d_x0`.
"""

from __future__ import annotations

import math

import numpy as np

from subid.methods.bd import fit_b_d_x0
from subid.methods.ct._ct_fit import (
    GROWTH_LIMIT,
    KEEP_UNSTABLE_RATIO,
    Record,
    ar_noise_model,
    growth,
    marginal_limit,
    predicted,
    refine_output_error,
    reflected,
)
from subid.model.statespace import StateSpace

__all__ = ["refine_model"]


def refine_model(model, rec: Record, s: dict):
    """Output-error refinement of a model of :func:`subid.ct_subspace`, prewhitened by an AR
    noise model of the output error when ``s['noise_model'] == 'ar'`` (Box-Jenkins / RIVC,
    module notes); ``s`` holds the method's settings."""
    feedthrough = model.info["feedthrough"]
    kw = dict(feedthrough=feedthrough, estimate_x0=s["estimate_x0"], offset=s["offset"])
    fit_kw = dict(kw, bd_method="simulation")     # B, D, x0, y0 for the refined (A, C)
    A, C = model.A, model.C
    info = dict(model.info)
    limit = marginal_limit(rec)
    unstable = bool(np.linalg.eigvals(A).real.max() > limit)
    # an unstable estimate kept by stability='auto' (it fit clearly better than its
    # reflection) is refined from its reflection, stable; the stable refined model
    # replaces it unless the unstable one still fits clearly better
    retry = unstable and s["stability"] != "none" and growth(rec) < GROWTH_LIMIT
    keep = retry or not unstable
    if retry:
        A = reflected(A, limit)
    A, C, diag = refine_output_error(A, C, rec, max_iterations=s["refine_iterations"],
                                             keep_stable=keep, **kw)
    if retry:
        fitted = fit_b_d_x0(A, C, rec, **fit_kw)
        r_u = info.get("b_residual_rms", math.inf)
        if fitted is None or r_u < KEEP_UNSTABLE_RATIO * fitted[3]["b_residual_rms"]:
            A, C = model.A, model.C          # the data demand the instability
            A, C, diag = refine_output_error(
                A, C, rec, max_iterations=s["refine_iterations"], keep_stable=False, **kw)
            keep = False
        else:
            info["stability"] = dict(info.get("stability") or {}, action="enforced",
                                     how="refined from the reflected poles: the stable "
                                         "model fits as well")
    noise = None
    if s["noise_model"] == "ar":
        if not rec.uniform:
            diag["noise_model"] = None
            diag["noise_model_note"] = ("not used: an AR model in sample steps needs a "
                                        "uniform grid")
        else:
            fitted = fit_b_d_x0(A, C, rec, **fit_kw)
            if fitted is not None:
                B, D, x0, diag_bd = fitted
                resid = rec.y - predicted(A, B, C, D, x0, diag_bd["y_offset"], rec)
                noise = ar_noise_model(resid, [t.size for t, *_ in rec.parts],
                                               rec.n_outputs)
            if noise is not None:
                A, C, d2 = refine_output_error(
                    A, C, rec, max_iterations=s["refine_iterations"], whiten=noise.apply,
                    keep_stable=keep, **kw)
                diag.update({f"whitened_{k}": v for k, v in d2.items()})
            diag["noise_model"] = None if noise is None else {
                "kind": "AR (per output, in sample steps, order by BIC)",
                "coefficients": [list(map(float, a)) for a in noise.coefficients]}
    fitted = fit_b_d_x0(A, C, rec, whiten=None if noise is None else noise.apply, **fit_kw)
    if fitted is None:
        return model
    B, D, x0, bd = fitted
    y0 = bd.pop("y_offset")
    info.update(diag, x0=x0, y_offset=y0, largest_real_part=float(
        np.linalg.eigvals(A).real.max()), **bd)
    info["conditions"] = dict(info.get("conditions") or {}, bd=bd["b_regression_condition"])
    return StateSpace(A, B, C, D, 0.0, input_names=model.input_names,
                      output_names=model.output_names, info=info, hold=model.hold)
