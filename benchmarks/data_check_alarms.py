"""The data check alone on every scenario bundle of a seed: its alarms against the truths.

    ./drape exec python3 benchmarks/data_check_alarms.py results/scenarios/seed51

For each scenario folder (``sNN/bundle`` and ``sNN/truth.json``, as
``benchmarks/scenarios/run.py`` leaves them) it runs
:func:`~fenicsx_drape.diagnosis.data_check.data_check` — no fit, no forming run — and prints
each measurement named suspect with its ``why``, then the counts: scenarios whose data are
another part's (the truth class "other part") named or not, and false alarms (a suspect
measurement in any other scenario).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from fenicsx_drape.diagnosis.data_check import data_check
from fenicsx_drape.forming.case.format import case_for_test
from fenicsx_drape.measurements.bundle import load_bundle


def main(root: Path) -> int:
    named = missed = alarms = checked = 0
    for folder in sorted(p for p in root.iterdir() if (p / "bundle").is_dir()):
        truth = json.loads((folder / "truth.json").read_text())
        start = time.process_time()
        entries = data_check(load_bundle(folder / "bundle", read_case=case_for_test))
        seconds = time.process_time() - start
        bad = [e for e in entries if e["suspect"]]
        other = truth.get("class") == "other part"
        checked += 1
        if other:
            named += bool(bad)
            missed += not bad
        else:
            alarms += bool(bad)
        mark = ("named" if bad else "MISSED") if other else ("FALSE ALARM" if bad else "ok")
        print(f"{folder.name} {truth.get('class')} {truth.get('part')} "
              f"{'+'.join(truth.get('kinds', []))}: {mark} ({seconds:.1f} CPU-s)")
        for e in bad:
            print(f"    {e['test']}/{e['measurement']}: {e['why']}")
    print(f"{checked} bundles: another part's named {named}, missed {missed}; "
          f"false alarms {alarms}")
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1])))
