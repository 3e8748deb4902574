"""The ``save FILE`` / ``compare FILE`` command line of the ``bench/*_identity.py`` scripts.

Each script fits its models (``run``) and reads two sets of them (``compare``); this
module holds the rest: ``save`` writes ``run``'s results to FILE, every other mode the
script accepts (``compare``, and ``floor`` for ``poly_identity.py``) fits again, reads
FILE and exits 0 when ``compare(saved, new)`` says the two agree, 1 when not. A baseline
comes from one tree and the comparison from another (``PYTHONPATH``), one process at a
time (cores are shared).
"""

from __future__ import annotations

import pickle


def _save_pickle(path, results):
    with open(path, "wb") as fh:
        pickle.dump(results, fh)


def _load_pickle(path):
    with open(path, "rb") as fh:
        return pickle.load(fh)


def main(argv, run, compare, *, modes=("compare",), save=_save_pickle, load=_load_pickle):
    """Run ``argv = [script, MODE, FILE, ...]``; the exit status.

    ``run(mode)`` fits the models (``mode``: ``'save'`` or one of ``modes``);
    ``compare(saved, new)`` prints the differences and returns whether the two agree.
    ``save(path, results)`` and ``load(path)`` write and read FILE (a pickle unless
    given).
    """
    if len(argv) < 3 or argv[1] not in ("save", *modes):
        print(f"usage: python {argv[0]} {{{','.join(('save', *modes))}}} FILE ...")
        return 2
    mode, path = argv[1], argv[2]
    if mode == "save":
        save(path, run(mode))
        return 0
    saved = load(path)
    return 0 if compare(saved, run(mode)) else 1
