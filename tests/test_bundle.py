"""The measurement-bundle loader: valid bundles load whole, each malformation is named."""

import math
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fenicsx_drape.measurements.bundle import BundleError, derived_tows, load_bundle, write_bundle

TOML = """\
# a small bundle
[bundle]
name = "twill"
material = "4x4 twill"
tows_per_mm = 0.71

[[test]]
id = "tensile-warp"
kind = "tensile"
file = "tensile.csv"
gauge_length_mm = 100.0
width_mm = 25.0
tows = 17.8
speed_mm_per_min = 2.0

[[test]]
id = "bias-10"
kind = "bias_extension"
file = "bias_10.csv"
length_mm = 210.0
width_mm = 70.0
speed_mm_per_min = 10.0
humidity_pct = 40.0
operator = "AB"

[test.conditions]
temperature_C = 20.0

[[test]]
id = "hemisphere"
kind = "forming"
file = "grid.csv"
geometry = "hemisphere"
sheet_mm = 240.0
travel_mm = 80.0
duration_s = 40.0
holder_force_N = 133.0
"""


def table(columns: dict[str, np.ndarray], comment: str = "") -> str:
    lines = [f"# {comment}"] if comment else []
    lines.append(",".join(columns))
    lines += [",".join(f"{v:.10g}" for v in row) for row in zip(*columns.values())]
    return "\n".join(lines) + "\n"


def tensile_csv() -> str:
    t = np.linspace(0.0, 9.0, 10)
    return table({"time_s": t, "displacement_mm": t * 2.0 / 60.0, "force_N": 100.0 * t},
                 "tensile test")


def bias_csv() -> str:
    t = np.linspace(0.0, 300.0, 7)
    return table({"time_s": t, "displacement_mm": t * 10.0 / 60.0, "force_N": 0.02 * t,
                  "force_sd_N": np.full(7, 0.1), "marker": np.zeros(7)})


def grid_csv() -> str:
    i, j = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
    x0, y0 = 10.0 * i.ravel(), 10.0 * j.ravel()
    return table({"i": i.ravel(), "j": j.ravel(), "x0_mm": x0, "y0_mm": y0, "x_mm": x0,
                  "y_mm": y0, "z_mm": np.zeros(9)})


@pytest.fixture
def bundle_dir(tmp_path: Path) -> Path:
    (tmp_path / "bundle.toml").write_text(TOML)
    (tmp_path / "tensile.csv").write_text(tensile_csv())
    (tmp_path / "bias_10.csv").write_text(bias_csv())
    (tmp_path / "grid.csv").write_text(grid_csv())
    return tmp_path


def line_of(text: str, needle: str) -> int:
    return next(n for n, line in enumerate(text.splitlines(), 1) if needle in line)


def test_valid_bundle_loads(bundle_dir):
    b = load_bundle(bundle_dir)
    assert b.name == "twill" and b.tows_per_mm == 0.71
    assert [t.id for t in b.tests] == ["tensile-warp", "bias-10", "hemisphere"]
    tensile, bias, form = b.tests
    assert tensile.tows == 17.8 and not tensile.tows_derived
    np.testing.assert_allclose(tensile.force_N, 100.0 * np.linspace(0, 9, 10))
    # bias tows derived as l_t·W/√2 and said so
    assert bias.tows_derived and bias.tows == pytest.approx(0.71 * 70 / math.sqrt(2))
    assert any("derived" in n and "bias-10" in n for n in b.notes)
    # unknown keys kept as conditions (numeric) or notes, and reported with their line
    assert bias.conditions == {"humidity_pct": 40.0, "temperature_C": 20.0}
    assert bias.notes == {"operator": "AB"}
    report = b.report()
    assert f"bundle.toml:{line_of(TOML, 'humidity_pct')}:" in report
    assert "operator" in report and "'marker'" in report
    assert bias.force_sd_N is not None and bias.column("marker") is not None
    assert form.geometry == "hemisphere" and form.forming["holder_force_N"] == 133.0
    assert form.columns["z_mm"].shape == (9,)
    with pytest.raises(ValueError):
        bias.force_N[0] = 1.0  # columns are read-only


def test_the_holders_friction_condition_has_one_name_the_earlier_one_still_reads(bundle_dir):
    """A forming test's condition ``mu`` (the holder's μ, as ``drape form`` writes it); the
    earlier ``friction_coefficient`` is read as ``mu``, with a note naming the file and test."""
    path = bundle_dir / "bundle.toml"
    path.write_text(TOML + "\n[test.conditions]\nfriction_coefficient = 0.25\n")
    with pytest.warns(FutureWarning, match=r"bundle.toml:.*'hemisphere'.* 'friction_coefficient' "
                      r"is now called 'mu'"):
        form = load_bundle(bundle_dir).tests[2]
    assert form.conditions == {"mu": 0.25}
    path.write_text(TOML + "\n[test.conditions]\nmu = 0.25\n")
    assert load_bundle(bundle_dir).tests[2].conditions == {"mu": 0.25}


def test_windows_files_load(bundle_dir):
    """A byte-order mark and CRLF line ends (spreadsheet exports) are not problems."""
    for name in ("bundle.toml", "tensile.csv"):
        path = bundle_dir / name
        path.write_bytes(b"\xef\xbb\xbf" + path.read_text().replace("\n", "\r\n").encode())
    assert load_bundle(bundle_dir).tests[0].n_rows == 10


def test_paper_tow_counts():
    # section 3.2: 17.8 tows in the 25 mm tensile specimen, 35.3 in the 70 mm bias one
    assert derived_tows("tensile", 0.71, 25.0) == pytest.approx(17.8, rel=0.01)
    assert derived_tows("bias_extension", 0.71, 70.0) == pytest.approx(35.3, rel=0.01)


def test_roundtrip(bundle_dir, tmp_path):
    b = load_bundle(bundle_dir)
    out = write_bundle(b, tmp_path / "copy", comment="copied")
    c = load_bundle(out)
    assert [t.id for t in c.tests] == [t.id for t in b.tests]
    for s, t in zip(b.tests, c.tests):
        assert s.kind == t.kind and s.tows == pytest.approx(t.tows or s.tows)
        assert s.conditions == t.conditions and s.notes == t.notes
        for name, col in s.columns.items():
            np.testing.assert_array_equal(col, t.columns[name])


def expect(bundle_dir: Path, file: str, line: int | None, *phrases: str) -> BundleError:
    with pytest.raises(BundleError) as info:
        load_bundle(bundle_dir)
    message = str(info.value)
    where = f"{bundle_dir / file}:" + (f"{line}:" if line is not None else "")
    assert where in message, message
    for phrase in phrases:
        assert phrase in message, message
    return info.value


# Each malformation of bundle.toml: (replace this, by that, the message must contain). The
# message points at the changed line, or at its table's header when a key is missing.
TOML_CASES = [
    ('kind = "bias_extension"', 'kind = "trellis"', "unknown test kind 'trellis'"),
    ('id = "hemisphere"', 'id = "bias-10"', "used twice"),
    ("length_mm = 210.0", "length_cm = 21.0", "length must be given in mm"),
    ("temperature_C = 20.0", "temperature_K = 293.0", "temperature must be given in C"),
    ("temperature_C = 20.0", 'temperature_C = "warm"', "must be a finite number"),
    ("gauge_length_mm = 100.0\n", "", "a tensile test needs gauge_length_mm"),
    ("gauge_length_mm = 100.0", "gauge_length_mm = -100.0", "must be a positive number"),
    ("gauge_length_mm = 100.0", "gauge_length_mm = nan", "must be a positive number"),
    ("tows = 17.8", "tows = 1.78", "contradicts tows_per_mm"),
    ("speed_mm_per_min = 2.0", "speed_mm_per_min = 120.0", "inconsistent units"),
    ('name = "twill"', "label = 3", "[bundle] needs name"),
    ('geometry = "hemisphere"\n', "", "a forming test needs geometry"),
]


def header_line(text: str, position: int) -> int:
    """The line of the last table header before ``position``."""
    before = text[:position].splitlines()
    return max(n for n, line in enumerate(before, 1) if line.startswith("["))


@pytest.mark.parametrize("old, new, phrase", TOML_CASES)
def test_bad_toml(bundle_dir, old, new, phrase):
    assert old in TOML
    text = TOML.replace(old, new, 1)
    (bundle_dir / "bundle.toml").write_text(text)
    position = TOML.index(old)
    changed = text[:position].count("\n") + 1
    key = (old if phrase.startswith(("a ", "[")) else new).split("=")[0].strip()
    line = changed if key in text else header_line(text, position)
    err = expect(bundle_dir, "bundle.toml", line, phrase)
    assert len(err.problems) == 1


def test_missing_table_file_is_named_at_its_key(bundle_dir):
    text = TOML.replace("bias_10.csv", "missing.csv")
    (bundle_dir / "bundle.toml").write_text(text)
    err = expect(bundle_dir, "bundle.toml", line_of(text, 'file = "missing.csv"'),
                 "file = 'missing.csv': no such file", str(bundle_dir / "missing.csv"))
    assert ":0:" not in str(err)


def test_toml_syntax_error(bundle_dir):
    (bundle_dir / "bundle.toml").write_text(TOML.replace("tows = 17.8", "tows = = 17.8"))
    expect(bundle_dir, "bundle.toml", line_of(TOML, "tows = 17.8"), "not valid TOML")


def test_no_tows_anywhere(bundle_dir):
    text = TOML.replace("tows_per_mm = 0.71\n", "")
    (bundle_dir / "bundle.toml").write_text(text)
    expect(bundle_dir, "bundle.toml", line_of(text, 'id = "bias-10"') - 1, "needs tows")


def test_missing_bundle(tmp_path):
    with pytest.raises(BundleError, match=r"no bundle\.toml"):
        load_bundle(tmp_path)


# Each malformation of a CSV table: (file, rewrite of its text, line, message).
def _replace_line(text: str, n: int, new: str) -> str:
    lines = text.splitlines()
    lines[n - 1] = new
    return "\n".join(lines) + "\n"


CSV_CASES = [
    ("tensile.csv", lambda s: s.replace("force_N", "load"), 2, "missing column(s) force_N"),
    ("tensile.csv", lambda s: s.replace("force_N", "force_kN"), 2, "force must be given in N"),
    ("tensile.csv", lambda s: _replace_line(s, 5, "3,0.1,abc"), 5, "'abc' is not a number"),
    ("tensile.csv", lambda s: _replace_line(s, 6, "4,0.13,nan"), 6, "not a finite number"),
    ("tensile.csv", lambda s: _replace_line(s, 7, "5,0.16"), 7, "2 cells"),
    ("tensile.csv", lambda s: _replace_line(s, 9, "7.5,0.2,750"), 10, "must increase"),
    ("tensile.csv", lambda s: s.replace("time_s,", "time_s,time_s,"), 2, "duplicate"),
    ("tensile.csv", lambda s: "\n".join(s.splitlines()[:3]) + "\n", 2, "at least two"),
    ("bias_10.csv", lambda s: s.replace(",0.1,", ",0,", 1), 2, "force_sd_N must be positive"),
    ("grid.csv", lambda s: _replace_line(s, 3, "0,0.5,0,0,0,0,0"), 3, "must be integers"),
    ("grid.csv", lambda s: _replace_line(s, 4, "0,0,0,0,0,0,0"), 4, "appears twice"),
    ("grid.csv", lambda s: s.replace("z_mm", "z_m"), 1, "z must be given in mm"),
]


@pytest.mark.parametrize("file, edit, line, phrase", CSV_CASES)
def test_bad_csv(bundle_dir, file, edit, line, phrase):
    path = bundle_dir / file
    path.write_text(edit(path.read_text()))
    err = expect(bundle_dir, file, line, phrase)
    assert len(err.problems) == 1


def test_all_problems_reported_together(bundle_dir):
    (bundle_dir / "bundle.toml").write_text(TOML.replace('kind = "tensile"', 'kind = "x"'))
    path = bundle_dir / "bias_10.csv"
    path.write_text(_replace_line(path.read_text(), 4, "100,1,oops,0.1,0"))
    err = expect(bundle_dir, "bias_10.csv", 4, "'oops' is not a number", "unknown test kind")
    assert len(err.problems) == 2


FIXTURE_OK = [HealthCheck.function_scoped_fixture]  # each example rewrites the table anew


@settings(max_examples=40, deadline=None, suppress_health_check=FIXTURE_OK)
@given(row=st.integers(0, 9), column=st.integers(0, 2),
       cell=st.sampled_from(["", "x", "1..2", "nan", "inf", "-inf", "1e400", "0x10", "--1"]))
def test_any_bad_cell_is_named(bundle_dir, row, column, cell):
    """Hypothesis: a bad cell anywhere in the tensile table is reported at its line."""
    text = tensile_csv()
    lines = text.splitlines()
    cells = lines[2 + row].split(",")
    cells[column] = cell
    lines[2 + row] = ",".join(cells)
    (bundle_dir / "tensile.csv").write_text("\n".join(lines) + "\n")
    err = expect(bundle_dir, "tensile.csv", 3 + row)
    header = ["time_s", "displacement_mm", "force_N"][column]
    assert re.search(rf"column {header}: .* (not a number|not a finite number)", str(err))


@settings(max_examples=40, deadline=None, suppress_health_check=FIXTURE_OK)
@given(times=st.lists(st.floats(0, 100, allow_nan=False), min_size=3, max_size=12))
def test_time_order(bundle_dir, times):
    """Hypothesis: any table whose time does not strictly increase is rejected at that row."""
    n = len(times)
    text = table({"time_s": np.array(times), "displacement_mm": np.linspace(0, 0.3, n),
                  "force_N": np.linspace(0, 10, n)})
    (bundle_dir / "tensile.csv").write_text(text)
    (bundle_dir / "bundle.toml").write_text(TOML.replace("speed_mm_per_min = 2.0\n", "", 1))
    parsed = np.array([float(f"{t:.10g}") for t in times])
    bad = np.flatnonzero(np.diff(parsed) <= 0)
    if bad.size == 0:
        assert load_bundle(bundle_dir).tests[0].n_rows == n
    else:
        expect(bundle_dir, "tensile.csv", 3 + bad[0], "must increase")
