"""Jupyter summaries: ``_repr_html_`` and ``__repr__`` of models, records and
online identifiers."""

import html.parser

import numpy as np
import pytest

import subid
from subid import _repr


class _Checker(html.parser.HTMLParser):
    """Collects text and checks that every opened element is closed."""

    VOID = {"br", "hr", "img", "input", "meta", "link"}

    def __init__(self):
        super().__init__()
        self.stack, self.text = [], []

    def handle_starttag(self, tag, attrs):
        if tag not in self.VOID:
            self.stack.append(tag)

    def handle_startendtag(self, tag, attrs):
        pass

    def handle_endtag(self, tag):
        assert self.stack and self.stack[-1] == tag, (tag, self.stack[-5:])
        self.stack.pop()

    def handle_data(self, data):
        self.text.append(data)


def _parse(page: str) -> str:
    checker = _Checker()
    checker.feed(page)
    checker.close()
    assert checker.stack == []
    return " ".join(checker.text)


@pytest.fixture(scope="module")
def data():
    true = subid.systems.seed001_system()
    return subid.systems.simulate_data(true, 600, seed=3)


def test_statespace_html_names_order_channels_timing_stability(data):
    model = subid.ls_subspace(data, 3)
    text = _parse(model._repr_html_())
    assert "ls_subspace" in text or model.info["method"] in text
    assert "order" in text and " 3 " in f" {text} "
    assert "u1, u2" in text and "y1, y2" in text
    assert "discrete time, dt = 1" in text
    radius = float(np.max(np.abs(model.poles())))
    assert f"stable (spectral radius = {radius:.4g})" in text
    assert model._repr_html_().count("<svg") == 1      # the pole map


def test_statespace_html_says_the_direct_term_decision_and_the_covariance(data):
    from subid._repr import describe_feedthrough
    subspace = subid.ls_subspace(data, 3)
    text = _parse(subspace._repr_html_())
    line = describe_feedthrough(subspace.info["feedthrough"], input_names=["u1", "u2"],
                                output_names=["y1", "y2"])
    assert "direct term" in text and line in text
    assert "covariance" not in text                    # a subspace method's own model
    refined = subid.identify(data, 3, refine=False)
    text = _parse(refined._repr_html_())
    assert "confidence bounds available" in text
    plain = subid.StateSpace([[0.5]], [[1.0]], [[1.0]], [[0.0]], 1.0)
    text = _parse(plain._repr_html_())
    assert "direct term" not in text and "covariance" not in text


def test_unstable_and_continuous_models_say_so():
    unstable = subid.StateSpace([[1.2]], [[1.0]], [[1.0]], 0, dt=0.5)
    text = _parse(unstable._repr_html_())
    assert "unstable (spectral radius = 1.2)" in text
    assert "#d62728" in unstable._repr_html_()          # the pole outside drawn red
    ct = subid.StateSpace([[-2.0, 1.0], [0.0, -3.0]], [[0.0], [1.0]], [[1.0, 0.0]], 0, dt=0)
    text = _parse(ct._repr_html_())
    assert "continuous time (dt = 0)" in text and "stable (max Re(pole) = -2)" in text
    assert "#d62728" not in ct._repr_html_()


def test_large_models_skip_matrices():
    n = _repr.MAX_MATRIX_ORDER + 1
    big = subid.StateSpace(0.5 * np.eye(n), np.ones((n, 1)), np.ones((1, n)), 0, dt=1)
    assert "<b>A</b>" not in big._repr_html_()
    small = subid.StateSpace(0.5 * np.eye(2), np.ones((2, 1)), np.ones((1, 2)), 0, dt=1)
    assert "<b>A</b>" in small._repr_html_()


def test_iodata_html_statistics_and_offsets(data):
    text = _parse(data._repr_html_())
    assert "600" in text and "time counted in samples" in text
    assert f"{data.y[:, 1].std():.4g}" in text
    detrended = data.detrend()
    text = _parse(detrended._repr_html_())
    assert "removed offsets" in text
    assert str(np.round(data.u.mean(axis=0), 6).tolist()) in text
    stamped = subid.IOData(data.u[:50], data.y[:50], t=np.cumsum(np.linspace(1, 2, 50)))
    assert "non-uniform time stamps" in _parse(stamped._repr_html_())


def test_sparkline_keeps_extremes_of_long_signals():
    x = np.zeros(100_000)
    x[12345] = 7.0
    lo, hi = _repr._envelope(x)
    assert lo.size == _repr.SPARK_POINTS and hi.max() == 7.0 and lo.min() == 0.0


def test_online_identifiers_repr_and_html(data):
    rec = subid.RecursiveSubspace(3, 2, 2)
    assert repr(rec) == ("RecursiveSubspace(order=3, n_inputs=2, n_outputs=2, horizon="
                         "5, forgetting=1, dt=1, samples=0)")
    assert "no model yet: no samples yet" in _parse(rec._repr_html_())
    rec.update(data.u[:8], data.y[:8])
    assert "no model yet" in _parse(rec._repr_html_())    # too few samples, said why
    rec.update(data.u[8:], data.y[8:])
    text = _parse(rec._repr_html_())
    assert "current model" in text and "samples 600" in text.replace("  ", " ")
    ada = subid.AdaptiveIdentifier(2, 1, 1, dt=0.01)
    text = _parse(ada._repr_html_())
    assert "AdaptiveIdentifier" in text and "continuous time" in text
