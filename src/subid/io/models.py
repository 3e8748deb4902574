"""Model files: the JSON model file of :meth:`StateSpace.save` / :meth:`StateSpace.load`
(its encoding is :mod:`subid.model.codec`) and the MATLAB ``ss`` fields of
:meth:`StateSpace.to_mat` / :meth:`StateSpace.from_mat` (:mod:`subid.io.mat`).

Importing this module registers both formats in :mod:`subid.model.storage`, where the
model's file methods find them: the model imports nothing of :mod:`subid.io`.
"""

from __future__ import annotations

import os

from subid.errors import FileReadError, ModelError
from subid.io._files import atomic_write, read_regular
from subid.io._schema import parse_json
from subid.io.mat import read_mat_model, write_mat_model
from subid.model import storage
from subid.model.codec import to_json, to_json_value

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
    size = len(text.encode("utf-8"))
    if size > MAX_MODEL_BYTES:
        info = model.info
        bulky = sorted(info, key=lambda k: -len(to_json_value(info[k])))[:3]
        raise ModelError(f"the model file would be {size} bytes, more than the "
                         f"{MAX_MODEL_BYTES} bytes StateSpace.load reads; nothing was "
                         f"written. Remove bulky entries from model.info (the largest: "
                         f"{', '.join(map(repr, bulky))}) and save again")
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
    try:
        size = os.stat(path).st_size
    except (OSError, ValueError):                  # read_regular says what is wrong
        size = 0
    if size > MAX_MODEL_BYTES:
        raise FileReadError(f"{path} is {size} bytes, more than the {MAX_MODEL_BYTES} bytes "
                            "of the largest model file StateSpace.load reads (save writes "
                            "none larger): it is not a subid model file", path=path)
    raw = read_regular(path, what="model file", max_bytes=MAX_MODEL_BYTES)
    if not raw.strip():
        raise ModelError(f"model file '{path}' is empty")
    d = parse_json(raw, f"model file '{path}'", ModelError)
    try:
        return cls.from_dict(d)
    except ModelError as exc:
        raise ModelError(f"model file '{path}': {exc}") from None


storage.register("json", reader=load_model, writer=save_model)
storage.register("mat", reader=read_mat_model, writer=write_mat_model)
