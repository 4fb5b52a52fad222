"""Generated inputs: the expression language never fails in an unplanned way, and the aggregate
stage agrees with a brute-force computation for any in-order stream."""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from fleetlink.edge.stages import AggregateStage, ExpressionError, FilterStage, Sample
from fleetlink.edge.stages.expr import check_predicate, parse_expression
from tests.unit.edge.stages.messages import sample, status_value

S = 1_000_000_000
T0 = 1_700_000_000 * S

ATOMS = [
    "level",
    "battery",
    "mode",
    "data",
    "ranges",
    "names",
    "kidnap.is_kidnapped",
    "ranges[1]",
    "missing",
    "@robot",
    "@stamp_ns",
    "1",
    "2.5",
    "'dock'",
    "true",
    "false",
    "(",
    ")",
    "[",
    "]",
    ",",
    ".",
    "==",
    "!=",
    "<",
    "<=",
    ">",
    ">=",
    "&&",
    "||",
    "!",
    "+",
    "-",
    "*",
    "/",
    "%",
    "in",
    "any(",
    "all(",
    "len(",
    "size()",
    "min(",
    "max(",
    "abs(",
    "sqrt(",
    "isnan(",
    "@",
    "'",
    '"',
    "#",
    "=",
    "&",
]


@settings(max_examples=400, deadline=None)
@given(st.text(max_size=40))
def test_any_text_parses_or_gives_a_column(text: str) -> None:
    error: ExpressionError | None = None
    try:
        check_predicate(parse_expression(text), text)
    except ExpressionError as exc:
        error = exc
    if error is not None:
        assert 1 <= error.column <= len(text) + 1


@settings(max_examples=600, deadline=None)
@given(st.lists(st.sampled_from(ATOMS), min_size=1, max_size=12))
def test_token_soup_never_escapes_the_filter_stage(atoms: list[str]) -> None:
    text = " ".join(atoms)
    error: ExpressionError | None = None
    try:
        stage = FilterStage(text)
    except ExpressionError as exc:
        error = exc
    if error is not None:
        assert 1 <= error.column <= len(text) + 1
        return
    out = stage.process(sample(status_value()), 0)
    out += stage.process(sample({"level": None, "mode": 3, "data": "x", "ranges": {"a": 1}}), 0)
    counters = stage.counters
    assert counters.received == 2
    assert counters.passed + counters.dropped + counters.errors == 2
    assert len(out) == counters.passed


stamps = st.lists(st.integers(min_value=0, max_value=10 * S), min_size=1, max_size=60).map(sorted)
values = st.one_of(st.floats(min_value=-1e6, max_value=1e6), st.just(math.nan))


@settings(max_examples=200, deadline=None)
@given(stamps, st.data(), st.sampled_from([(S, S), (2 * S, S), (3 * S, S), (S, S // 4)]))
def test_aggregate_matches_brute_force(
    offsets: list[int], data: st.DataObject, shape: tuple[int, int]
) -> None:
    window, hop = shape
    xs = data.draw(st.lists(values, min_size=len(offsets), max_size=len(offsets)))
    stage = AggregateStage(["x"], ["count", "mean", "min", "max", "last", "stddev"], window, hop_ns=hop)
    out: list[Sample] = []
    for offset, x in zip(offsets, xs, strict=True):
        out += stage.process(sample({"x": x}, stamp_ns=T0 + offset), T0 + offset)
    out += stage.tick(T0 + 100 * S)
    got = {s.value["window_start_ns"]: s.value for s in out}
    expected: dict[int, list[tuple[int, float]]] = {}
    for offset, x in zip(offsets, xs, strict=True):
        t = T0 + offset
        for start in range((t - window) // hop * hop, t + 1, hop):
            if start <= t < start + window:
                expected.setdefault(start, []).append((t, x))
    assert sorted(got) == sorted(expected)
    for start, members in expected.items():
        record = got[start]
        finite = [x for _, x in members if not math.isnan(x)]
        assert record["count"] == len(members)
        assert record["x_count"] == len(finite)
        if not finite:
            assert record["x_mean"] is None
            continue
        mean = math.fsum(finite) / len(finite)
        spread = max(abs(v) for v in finite) + 1.0
        assert abs(record["x_mean"] - mean) <= 1e-9 * spread
        assert record["x_min"] == min(finite)
        assert record["x_max"] == max(finite)
        std = math.sqrt(math.fsum((v - mean) ** 2 for v in finite) / len(finite))
        assert abs(record["x_stddev"] - std) <= 1e-6 * spread
        last = [x for t, x in members if not math.isnan(x)][-1]  # in order: the last with the greatest stamp
        assert record["x_last"] == last
    assert stage.counters.late == 0
    assert stage.counters.nan == sum(1 for x in xs if math.isnan(x))
