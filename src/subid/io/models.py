"""Model files: the JSON model file of :meth:`StateSpace.save` / :meth:`StateSpace.load`
(its encoding is :mod:`subid.model.codec`) and the MATLAB ``ss`` fields of
:meth:`StateSpace.to_mat` / :meth:`StateSpace.from_mat` (:mod:`subid.io.mat`).

Importing this module registers both formats in :mod:`subid.model.storage`, where the
model's file methods find them: the model imports nothing of :mod:`subid.io`.
"""

from __future__ import annotations

import os

from subid.delay import absorb_delay, input_delay_of
from subid.errors import ModelError
from subid.io._files import atomic_write, read_regular
from subid.io._schema import parse_json
from subid.io.mat import read_mat_model, write_mat_model
from subid.model import storage
from subid.model.codec import to_json

#: Largest model file :meth:`StateSpace.load` reads (a model is a few matrices).
MAX_MODEL_BYTES = 256 * 2**20


def save_model(model, path) -> None:
    """Write ``model`` to the JSON file ``path``, atomically (:meth:`StateSpace.save`).

    Parameters
    ----------
    model : StateSpace
    path : str or os.PathLike
    """
    text = to_json(model)
    with atomic_write(path, "w", encoding="utf-8", what="model file") as fh:
        fh.write(text)


def load_model(path, cls):
    """A ``cls`` model read from the JSON file ``path`` (:meth:`StateSpace.load`).

    Parameters
    ----------
    path : str or os.PathLike
    cls : type
        The model class (:class:`StateSpace`).

    Returns
    -------
    StateSpace
    """
    path = os.fsdecode(path) if isinstance(path, bytes) else os.fspath(path)
    raw = read_regular(path, what="model file", max_bytes=MAX_MODEL_BYTES)
    if not raw.strip():
        raise ModelError(f"model file '{path}' is empty")
    d = parse_json(raw, f"model file '{path}'", ModelError)
    try:
        return cls.from_dict(d)
    except ModelError as exc:
        raise ModelError(f"model file '{path}': {exc}") from None


def _write_mat(model, path) -> None:
    # input delays become extra states: MATLAB's ss fields here carry none
    if input_delay_of(model) is not None:
        model = absorb_delay(model)
    write_mat_model(model, path)


storage.register("json", reader=load_model, writer=save_model)
storage.register("mat", reader=read_mat_model, writer=_write_mat)
