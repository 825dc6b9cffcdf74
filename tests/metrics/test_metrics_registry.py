"""The metric registry checks a spec when it is registered, and names the metric in the error."""
from __future__ import annotations

import pytest

from lfmbench.metrics import BLOCKS, REGISTRY, MetricSpec, register_metric


def _spec(**kw):
    base = dict(name="toy", version="1.0", reference="test", unit="1", higher_is_better=True, group="hdr",
                header="TOY", fn=lambda p, b, o: p.flatten(1).mean(1))
    return MetricSpec(**{**base, **kw})


@pytest.mark.parametrize("kw, why", [
    (dict(derive=lambda v: 0.0), "give fn or derive, not both"),
    (dict(fn=None, group="nogroup"), "no fn, no derive and no block for group 'nogroup'"),
    (dict(aggregate="pooled"), "aggregate must be 'mean', or 'pooled' with a weight"),
    (dict(show="screen"), "show must be console, table or none"),
    (dict(header=""), "a column header is needed"),
    (dict(fn=None, derive=lambda v: 0.0, inputs=("nope",)), r"derive inputs \['nope'\] are not registered"),
    (dict(name="psnr_mu"), "metric 'psnr_mu' is registered already"),
])
def test_a_bad_spec_is_refused_and_nothing_is_registered(kw, why):
    before = REGISTRY.names()
    with pytest.raises(ValueError, match=why):
        register_metric(_spec(**kw))
    assert REGISTRY.names() == before


def test_builtin_blocks_and_lookup_error():
    assert BLOCKS.names() == ("perceptual", "flicker", "region", "display")
    with pytest.raises(ValueError, match=r"^unknown metric 'nope'; valid: led_score, dropout_rate, "):
        REGISTRY.get("nope")
