"""Random values of every type for every setting, through the command line: the CLI answers
exit 0, 2 or 3 (2 with one line naming the field), never an internal error (exit 1), a
traceback or a hang."""

import dataclasses
import json
import math

import pytest

from bve_mj.cli import main
from bve_mj.config import SECTIONS

hypothesis = pytest.importorskip("hypothesis")
st = hypothesis.strategies

FIELDS = [(section, f.name) for section, cls in SECTIONS.items() for f in dataclasses.fields(cls)]


def _toml(value):
    """A TOML literal for ``value`` (the values the strategy draws)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {_toml(v)}" for k, v in value.items()) + "}"
    raise TypeError(value)


VALUES = st.one_of(
    st.booleans(),
    st.integers(min_value=-3, max_value=3),
    st.integers(min_value=2**31, max_value=2**70),
    st.integers(max_value=-(2**31)),
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=-1.0, max_value=1.0),
    st.text(max_size=8),
    st.lists(st.floats(min_value=-2.0, max_value=2.0), max_size=4),
    st.lists(st.lists(st.integers(min_value=-1, max_value=2), max_size=3), max_size=3),
    st.dictionaries(st.text(min_size=1, max_size=4), st.integers(0, 3), max_size=2),
)


@hypothesis.settings(max_examples=60, deadline=None, derandomize=True)
@hypothesis.given(field=st.sampled_from(FIELDS), value=VALUES)
def test_any_value_of_any_setting_gives_a_clear_answer(tmp_path_factory, field, value):
    section, name = field
    path = tmp_path_factory.mktemp("fuzz") / "settings.toml"
    path.write_text(f"[{section}]\n{name} = {_toml(value)}\n", encoding="utf-8")
    import contextlib
    import io

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(["paper", "--config", str(path), "--runs", "1", "--experiments", "E1", "--quiet"])
    text = err.getvalue().strip()
    assert code in (0, 2, 3), (section, name, value, code, text)
    assert "Traceback" not in text and "internal error" not in text, text
    if code == 2:
        assert len(text.splitlines()) == 1, text


@pytest.mark.parametrize(
    ("content", "field"),
    [
        (b"\xad\x00\xff binary", "config"),
        (b"[episode]\ninitial_error_m = 1e308\n", "episode.initial_error_m"),
        (b"[measurement]\nreference_range_m = 1.4e-45\n", "measurement.reference_range_m"),
        (b"[planner]\nstarts = 1099511627776\n", "planner.starts"),
        (b"[protocol]\nsteps = 1099511627776\n", "protocol.steps"),
    ],
)
def test_what_the_fuzzing_found_exits_2_naming_the_field(tmp_path, capsys, content, field):
    """The defects the fuzzing found at 1,500 examples (an internal error, an overflow, a
    collapsed covariance, runs without end), each kept as a case of its own."""
    path = tmp_path / "settings.toml"
    path.write_bytes(content)
    assert main(["paper", "--config", str(path), "--runs", "1", "--experiments", "E1", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"error: {field}" in err, err
