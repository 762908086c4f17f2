"""The diagnoses kept as reference reports, and the script that writes them.

Each case of :data:`CASES` is a bundle, a model and the ``diagnose`` options; its reference is
the report ``drape diagnose --json`` writes for it, less ``seconds`` (wall-clock), in
``tests/data/reference/<name>.json``. ``tests/test_reference_reports.py`` diagnoses the same
cases and checks the report field by field against the file: a change of the code that is
not meant to change what the diagnosis says must leave every field as it was.

Write the references again (when a change is meant to change the reports: the diff of the
JSON files is then what a reviewer reads)::

    ./drape exec python3 tests/reference_reports.py            # every case
    ./drape exec python3 tests/reference_reports.py NAME ...   # only these
    ./drape exec python3 tests/reference_reports.py --bundles  # the made bundles first

The shipped bundles (``demos/bundles/``) are diagnosed with the models the README and the
docs use. Two more are made by the project's simulator, as the tests make them, and kept as
files under ``tests/data/reference/bundles/`` (``--bundles`` writes them again): a set-up
error (the double dome on 20 mm cells with its ply laid at 4° where the case says 0°; its
tools are made by a Python script: read as trusted) and a stack whose plies slid (the
hemisphere's [0/90, ±45] stack) against a model of bonded plies.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "reference"
BUNDLES = DATA / "bundles"
VOLATILE = ("seconds", "cost")  # wall-clock and the cache's: not compared, not kept


@dataclasses.dataclass(frozen=True)
class Case:
    """One diagnosis kept as a reference."""

    bundle: Path  # the bundle folder
    model: Path | None  # MODEL.toml; None: the paper's model with Table 2's values
    candidates: tuple[str, ...] | None = None  # diagnose(candidates=...); None: all
    setup: tuple[str, ...] | None = None  # diagnose(setup=...); None: the default
    bench: bool = False  # too long for ``make test``: run by ``make bench``
    trust: bool = False  # its case's tools are made by code (``--trust``)


MODELS = ROOT / "demos" / "models"
CASES = {
    # The README's coupon command (rate dependence missing from the model).
    "twill-table2": Case(ROOT / "demos/bundles/twill-table2",
                         MODELS / "without_rate_dependence.toml"),
    # Real coupon curves of several labs and sizes: the consistency of the groups.
    "cao2008-plain-frames": Case(ROOT / "demos/bundles/cao2008-plain-frames", None),
    # The README's lab command (tow buckling missing from the model).
    "octagon-lab": Case(ROOT / "demos/bundles/octagon-lab",
                        MODELS / "without_tow_buckling.toml", bench=True),
    # A set-up error: the ply laid at 4°, the set-up stage and one effect tried with it.
    "setup-turned-ply": Case(BUNDLES / "setup-turned-ply", None, candidates=("tool_friction",),
                             setup=("ply_angle_deg",), trust=True, bench=True),
    # A stack whose plies slid, against bonded plies; one candidate a stack cannot take.
    "stack-sliding": Case(BUNDLES / "stack-sliding", None,
                          candidates=("interply_friction", "shear_tension_coupling")),
}


def _relative(value):
    """``value`` with the repository's folder written as ``<root>`` in its strings."""
    if isinstance(value, dict):
        return {k: _relative(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_relative(v) for v in value]
    return value.replace(str(ROOT), "<root>") if isinstance(value, str) else value


def report_of(case: Case) -> dict:
    """The case's report as ``REPORT.json`` holds it, less :data:`VOLATILE`.

    Paths in it are written from the repository's folder (``<root>/demos/...``), so that
    the reference holds wherever the repository is.
    """
    from fenicsx_drape.diagnosis import diagnose
    from fenicsx_drape.forming.case import case_for_test
    from fenicsx_drape.measurements.bundle import load_bundle
    from fenicsx_drape.model import default_model, load_model
    from fenicsx_drape.provenance import json_text
    from fenicsx_drape.trust import trusting

    with trusting(case.trust):
        bundle = load_bundle(case.bundle, read_case=case_for_test)
        model = load_model(case.model) if case.model else default_model()
        report = diagnose(bundle, model, candidates=case.candidates, setup=case.setup)
    plain = json.loads(json_text(report))
    return _relative({k: v for k, v in plain.items() if k not in VOLATILE})


def make_bundles(names) -> None:
    """Write the made bundles (module doc) of the cases ``names`` with the project's simulator."""
    from fenicsx_drape.diagnosis.synthetic import synthetic_case_test, write_case_bundle
    from fenicsx_drape.forming.case import PlySpec, load_case, with_overrides
    from fenicsx_drape.model import default_model

    model = default_model()
    if "setup-turned-ply" in names:
        stated = load_case(ROOT / "meshes/double_dome/case.toml", cell_mm=20.0, step_mm=4.0)
        test = synthetic_case_test(model, with_overrides(stated, ply_angle_deg=4.0),
                                   sd_mm=0.3, seed=41, full=True)
        write_case_bundle("setup-turned-ply", [dataclasses.replace(test, forming_case=stated)],
                          BUNDLES / "setup-turned-ply")
    if "stack-sliding" in names:
        stack = load_case(ROOT / "meshes/hemisphere/stack_0_45.toml", cell_mm=30.0,
                          duration_s=8.0, mu=0.3)
        stack = dataclasses.replace(stack, plies=(PlySpec(0.0, 0.3), PlySpec(45.0, 0.3)))
        sliding = model.with_effects("interply_friction")
        tests = [synthetic_case_test(sliding, stack, test_id=f"ply{k}", ply=k, seed=k)
                 for k in (1, 2)]
        write_case_bundle("stack-sliding", tests, BUNDLES / "stack-sliding")


def main(argv: list[str]) -> int:
    """Write the reference reports of the cases named (all by default)."""
    bundles = "--bundles" in argv
    argv = [a for a in argv if a != "--bundles"]
    if bundles:
        make_bundles(argv or CASES)
    unknown = [a for a in argv if a not in CASES]
    if unknown:
        print(f"unknown case(s) {unknown}; known: {', '.join(CASES)}", file=sys.stderr)
        return 2
    DATA.mkdir(parents=True, exist_ok=True)
    for name in argv or CASES:
        report = report_of(CASES[name])
        (DATA / f"{name}.json").write_text(json.dumps(report, indent=1, ensure_ascii=False)
                                           + "\n")
        print(f"{name}: missing_effect {report['missing_effect']}, "
              f"setup_error {report.get('setup_error')}", flush=True)
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    raise SystemExit(main(sys.argv[1:]))
