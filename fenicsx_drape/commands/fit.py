"""``drape fit BUNDLE [--model MODEL.toml] --out DIR``: identify a model's parameters.

The same in Python: ``write_fit(fit(load_bundle(BUNDLE), load_model(MODEL)), DIR)``; with
``--consistency``, also ``consistency(bundle, result)`` (calibration.agreement). A bundle's
``interply_friction`` tests are fitted by ``calibration.interply.fit_interply`` and written as
the ``[interply]`` table of a stack's case file (``interply.toml``, ``interply.json``).
"""

from __future__ import annotations

import argparse


def configure(parser: argparse.ArgumentParser) -> None:
    """Options of ``drape fit``."""
    parser.add_argument("bundle", help="measurement bundle folder (bundle.toml + CSV tables)")
    parser.add_argument("--model", help="MODEL.toml: effects, plugins, start or fixed "
                        "parameters (default: the paper's model, Table 2 as the start)")
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--warm-start", action="store_true",
                        help="start from the model's parameter values instead of the "
                        "curve-feature guess of section 3.2")
    parser.add_argument("--no-global", action="store_true",
                        help="skip the global stage (the starts from curve features, Table 2, "
                        "MODEL.toml and Sobol points searched before the local least squares)")
    parser.add_argument("--tests", nargs="+", metavar="ID", help="fit only these tests")
    parser.add_argument("--consistency", nargs="*", metavar="BY",
                        choices=("test", "lab", "size", "kind"),
                        help="after the fit, leave out each test, lab, size or kind in turn, "
                        "refit the rest and predict it (default all four; written to "
                        "consistency.json): a lab offset or size effect against missing physics")
    parser.add_argument("--max-iterations", type=int, default=200,
                        help="cap on the optimiser's iterations per block (default 200)")


def run(args: argparse.Namespace) -> int:
    """Fit, print progress and the errors, write the outputs."""
    from fenicsx_drape.calibration.fitting import fit, write_fit
    from fenicsx_drape.calibration.sensitivity import format_table
    from fenicsx_drape.cli import load_bundle_reported
    from fenicsx_drape.effects import COUPON_KINDS
    from fenicsx_drape.model import default_model, load_model

    bundle = load_bundle_reported(args.bundle)
    model = load_model(args.model) if args.model else default_model()
    chosen = [t for t in bundle.tests if args.tests is None or t.id in args.tests]
    if any(t.kind == "interply_friction" for t in chosen):
        _fit_interply(chosen, args.out)
        if not any(t.kind in COUPON_KINDS for t in chosen):
            return 0
    result = fit(bundle, model, progress=print, initial_guess_from_features=not args.warm_start,
                 tests=args.tests, max_iterations=args.max_iterations,
                 global_stage=False if args.no_global else None)
    for kind, e in result.errors_per_kind().items():
        print(f"{kind}: mean |error| {e['mean_abs_N']:.3g} N ({e['mean_abs_pct']:.2g} %)")
    for test_id, noise in result.noise.items():
        print(f"noise of {test_id}: {noise['says']}")
    print(f"normalised error {result.normalised:.3g} (1 = noise floor), "
          f"{result.seconds:.1f} s")
    print("sensitivities (Table 2: relative change per relative change of the parameter)")
    print(format_table(result.sensitivity))
    out = write_fit(result, args.out)
    print(f"wrote {out}/model.toml, report.json, sensitivity.csv, fit_*.png")
    if args.consistency is not None:
        from fenicsx_drape.calibration.agreement import GROUPINGS, consistency
        from fenicsx_drape.provenance import write_json

        report = consistency(bundle, result, by=args.consistency or GROUPINGS, progress=print)
        write_json(out / "consistency.json", report)
        print(f"consistency: {report['verdict']}: {report['says']}")
        print(f"wrote {out}/consistency.json")
    return 0


def _fit_interply(tests, out_dir) -> None:
    """Fit the inter-ply law to the interply_friction tests; write interply.toml and .json."""
    from pathlib import Path

    from fenicsx_drape.calibration.interply import fit_interply
    from fenicsx_drape.provenance import atomic_write_text, write_json, write_provenance

    result = fit_interply(tests)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    law = result.law
    # The names of interply.toml's (and a case's [interply]) keys: one name per value.
    print(f"inter-ply friction: tau0_MPa = {law.tau0_MPa:.4g}, mu_ply = {law.mu_ply:.4g}, "
          f"eta_f_MPa_s_per_mm = {law.eta_f_MPa_s_per_mm:.4g}; normalised error "
          f"{result.normalised:.3g} (1 = noise floor)")
    for name, why in result.held.items():
        print(f"  {name} held at {getattr(law, name):g}: {why}")
    atomic_write_text(out / "interply.toml", "# the [interply] table of a stack's case file, "
                      "fitted by drape fit\n" + result.toml())
    write_json(out / "interply.json", result.report())
    write_provenance(out, interply=result.report(), tests=[t.id for t in tests
                                                           if t.kind == "interply_friction"])
    print(f"wrote {out}/interply.toml, interply.json")
