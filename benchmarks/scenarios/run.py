"""The scenario benchmark: how often is the README's diagnose command right on lab bundles?

    ./drape exec python3 benchmarks/scenarios/run.py --seed 51 --count 48 --docs docs/scenarios.md

For each scenario of the seed (:mod:`generate`: a lab-style bundle, the model handed, the
hidden truth) it runs the README's command exactly as printed, with its default options,

    ./drape diagnose BUNDLE --model MODEL.toml --json REPORT.json

each with a cache folder of its own, emptied first (so that every diagnosis forms its own
runs: the seconds are a cold cache's, and the runs it formed are counted), classifies the
answer (:mod:`classify`) and writes the confusion table — truth class × answer — with every
scenario's errors, seconds and forming runs and every wrong answer with why, to ``--docs``
(between the page's ``scenarios:begin`` and ``scenarios:end`` marks) and to
``WORK/results.json``. Truths are formed once and kept in ``WORK/truths`` by their parameters;
a scenario whose ``REPORT.json`` exists is not diagnosed again with ``--resume``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import sqlite3
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(HERE))

import classify
import generate

BEGIN, END = "<!-- scenarios:begin -->", "<!-- scenarios:end -->"


def cpu_children() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def runs_in(cache: Path) -> int | None:
    """The forming runs a diagnosis stored in its (fresh) cache folder."""
    db = cache / "cache.db"
    if not db.is_file():
        return None
    with sqlite3.connect(db) as con:
        return int(con.execute("select count(*) from Cache").fetchone()[0])


def diagnose(folder: Path, say=print) -> dict:
    """Run the README's command on one scenario's bundle; the run's numbers."""
    cache = folder / "runs"
    shutil.rmtree(cache, ignore_errors=True)
    report = folder / "REPORT.json"
    report.unlink(missing_ok=True)
    command = ["./drape", "diagnose", str(folder / "bundle"), "--model",
               str(folder / "model.toml"), "--json", str(report)]
    start, cpu = time.perf_counter(), cpu_children()
    load = os.getloadavg()[0]
    with open(folder / "diagnose.log", "w") as log:
        done = subprocess.run(command, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT,
                              env={**os.environ, "DRAPE_CACHE": str(cache)}, check=False)
    out = {"command": " ".join(command), "exit": done.returncode,
           "seconds": time.perf_counter() - start, "cpu_seconds": cpu_children() - cpu,
           "runs": runs_in(cache), "load": [load, os.getloadavg()[0]]}
    shutil.rmtree(cache, ignore_errors=True)
    (folder / "diagnose.json").write_text(json.dumps(out, indent=1))
    return out


def score(record: dict, folder: Path) -> dict:
    """The scenario's answer, label and verdict (right, why) from its report."""
    run = json.loads((folder / "diagnose.json").read_text())
    if run["exit"] != 0 or not (folder / "REPORT.json").is_file():
        tail = (folder / "diagnose.log").read_text().splitlines()[-3:]
        return {**run, "label": "failed", "right": False,
                "why": f"exit status {run['exit']}: " + " | ".join(tail)}
    report = json.loads((folder / "REPORT.json").read_text())
    ans = classify.answer(report)
    right, why = classify.judge(record, report)
    named = next((c for c in report.get("candidates", [])
                  if c["effect"] == report.get("missing_effect")), None)
    return {**run, "label": classify.label(ans, record["expected"]), "right": right,
            "why": why, "answer": {k: v for k, v in ans.items() if k != "conclusion"},
            "conclusion": ans["conclusion"],
            "baseline": report["baseline"]["error"]["normalised"],
            "after": named["error_after"]["normalised"] if named else None,
            "diagnosis_seconds": report.get("seconds")}


# --------------------------------------------------------------------------------------------
# The docs' table


def hidden_text(r: dict) -> str:
    parts = []
    if r.get("hidden_effect"):
        extra = ", ".join(f"{k} {v}" for k, v in (r.get("effect_parameters") or {}).items())
        parts.append(r["hidden_effect"] + (f" ({extra})" if extra else ""))
    s = r.get("setup")
    if s:
        v = (f"×{s['factor']}" if "factor" in s else s["value"])
        parts.append(f"{s['parameter']} {v}")
    if r.get("other_part"):
        parts.append(f"{r['other_part']['kind']} of the {r['other_part']['part']}")
    if r["class"] == "discretisation":
        parts.append("shear by finite differences" if r["detail"] == "fd" else "finer truth")
    return "; ".join(parts) or "nothing"


def answer_text(s: dict) -> str:
    a = s.get("answer")
    if not a:
        return s["label"]
    bits = []
    if a["data"]:
        bits.append("data: " + ", ".join(a["data"]))
    if a["setup"]:
        v = a.get("setup_value") or {}
        bits.append(f"{a['setup']} {classify._num(v.get('fitted'))}")
    if a["effects"]:
        bits.append(" + ".join(a["effects"]))
    if not bits:
        bits.append(s["label"])
    return "; ".join(bits)


def trials_text(r: dict) -> str:
    t = r["trials"]
    if len(t) == 1:
        return "1"
    for key, unit in (("temperature_C", "°C"), ("duration_s", "s"), ("holder_force_N", "N")):
        values = [x.get(key) for x in t]
        if len(set(values)) > 1:
            return "2: " + "/".join(f"{v:g}" for v in values) + f" {unit}"
    return str(len(t))


def signal_text(r: dict) -> str:
    """The signal; for a set-up error with an effect, each part's own after it (set-up / effect)."""
    parts = r.get("signal_parts")
    if not parts:
        return f"{r['signal']:.1f}"
    return f"{r['signal']:.1f} ({parts['setup']:.1f} / {parts['effect']:.1f})"


def kinds_text(r: dict) -> str:
    return "+".join("shear (fd)" if k == "shear" and r.get("shear_mode") == "fd" else k
                    for k in r["kinds"])


def table(records: list[dict], scores: dict[str, dict], command: str) -> str:
    done = [r for r in records if r["id"] in scores]
    left = [r for r in records if r.get("left_out")]
    lines = [BEGIN, "", f"Made by `{command}` ({len(done)} scenarios diagnosed"
             + (f", {len(left)} left out" if left else "") + ").", ""]
    # the confusion table
    used = [lab for lab in (*classify.LABELS, "failed")
            if any(scores[r["id"]]["label"] == lab for r in done)]
    lines.append("| truth \\ answer | " + " | ".join(used) + " | right |")
    lines.append("| --- | " + " | ".join("---" for _ in used) + " | --- |")
    total_right = 0
    for cls in generate.CLASSES:
        rows = [r for r in done if r["class"] == cls]
        if not rows:
            continue
        right = sum(scores[r["id"]]["right"] for r in rows)
        total_right += right
        cells = [str(sum(scores[r["id"]]["label"] == lab for r in rows) or "") for lab in used]
        lines.append(f"| {cls} | " + " | ".join(cells) + f" | {right}/{len(rows)} |")
    lines.append("")
    n = len(done)
    lines.append(f"**Right: {total_right} of {n} ({100 * total_right / max(n, 1):.0f} %).**")
    nothing = [r for r in done if not r.get("hidden_effect") and not r.get("setup")
               and not r.get("other_part")]
    bad_nothing = [r for r in nothing if scores[r["id"]]["label"] in
                   ("the hidden effect", "another effect", "write a user law",
                    "set-up and effect")]
    effect_only = [r for r in done if r.get("hidden_effect") and not r.get("setup")]
    bad_effect = [r for r in effect_only if (scores[r["id"]].get("answer") or {}).get("setup")]
    lines.append(f"Where nothing is missing ({len(nothing)}), an effect or \"write a user law\" "
                 f"in {len(bad_nothing)}; where only an effect is missing ({len(effect_only)}),"
                 f" a set-up error in {len(bad_effect)}.")
    secs = [scores[r["id"]]["seconds"] for r in done]
    cpus = [scores[r["id"]]["cpu_seconds"] for r in done]
    runs = [scores[r["id"]]["runs"] or 0 for r in done]
    if secs:
        big = max(done, key=lambda r: scores[r["id"]]["seconds"])
        mid = sorted(done, key=lambda r: scores[r["id"]]["seconds"])[len(done) // 2]
        lines.append(
            f"Median scenario {statistics.median(secs):.0f} s wall "
            f"({statistics.median(cpus):.0f} s CPU, {statistics.median(runs):.0f} forming runs;"
            f" {mid['id']}: {scores[mid['id']]['runs']} runs), the largest "
            f"{scores[big['id']]['seconds']:.0f} s ({big['id']}: "
            f"{scores[big['id']]['cpu_seconds']:.0f} s CPU, {scores[big['id']]['runs']} runs); "
            f"all diagnoses {sum(secs) / 60:.0f} min wall, {sum(cpus) / 60:.0f} min CPU.")
    lines += ["", "| scenario | truth | part | truth's net | kinds | trials | answer | right |"
              " baseline | after | signal | net error | s | CPU s | runs |",
              "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
              " --- | --- |"]
    for r in done:
        s = scores[r["id"]]
        after = "" if s.get("after") is None else f"{s['after']:.2f}"
        base = "" if s.get("baseline") is None else f"{s['baseline']:.2f}"
        net = f"{r['net']} ({r['truth_cell_mm']:g} mm)"
        net_error = "failed" if r["net_error"] is None else f"{r['net_error']:.1f}"
        part = r["part"].replace("_", " ") + (" stack" if r.get("stack") else "")
        lines.append(
            f"| {r['id']} | {r['class']}: {hidden_text(r)} | {part} | {net} | {kinds_text(r)} |"
            f" {trials_text(r)} | {answer_text(s)} | {'yes' if s['right'] else '**no**'} | "
            f"{base} | {after} | {signal_text(r)} | {net_error} | "
            f"{s['seconds']:.0f} | {s['cpu_seconds']:.0f} | {s['runs']} |")
    wrong = [r for r in done if not scores[r["id"]]["right"]]
    lines += ["", f"Wrong answers ({len(wrong)}):", ""]
    for r in wrong:
        lines.append(f"- **{r['id']}** ({r['class']}: {hidden_text(r)}; {r['part']}, "
                     f"{kinds_text(r)}): {scores[r['id']]['why']}.")
    if left:
        lines += ["", "Left out (the hidden effect or set-up error, or a part of both, never "
                  f"moved the lab's measures by {generate.SHOW:g} × the noise, or its runs "
                  "failed):", ""]
        for r in left:
            sig = ", ".join(f"{a.get('part')} {a.get('signal', float('nan')):.2f}" + (
                " ({setup:.2f} / {effect:.2f})".format(**a["signal_parts"])
                if a.get("signal_parts") else "") for a in r["attempts"] if "signal" in a)
            what = "; ".join(x for x in (r.get("hidden_effect"),
                                         (r.get("setup") or {}).get("parameter")) if x)
            lines.append(f"- {r['id']} ({r['class']}: {what}): {r['left_out']}"
                         + (f" (signal by part: {sig})" if sig else "") + ".")
    lines += ["", END]
    return "\n".join(lines)


def write_docs(path: Path, text: str) -> None:
    page = path.read_text()
    if BEGIN in page and END in page:
        page = page[:page.index(BEGIN)] + text + page[page.index(END) + len(END):]
    else:
        page = page.rstrip() + "\n\n" + text + "\n"
    path.write_text(page)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=51)
    parser.add_argument("--count", type=int, default=48)
    parser.add_argument("--only", nargs="*", help="scenario ids (e.g. s01 s07)")
    parser.add_argument("--work", type=Path, default=ROOT / "results" / "scenarios")
    parser.add_argument("--docs", type=Path, help="write the table into this page")
    parser.add_argument("--generate-only", action="store_true")
    parser.add_argument("--resume", action="store_true",
                        help="keep the reports of scenarios already diagnosed")
    args = parser.parse_args(argv)
    work = args.work.resolve()
    cache = work / "truths"
    say = lambda line: print(line, flush=True)  # noqa: E731
    start = time.perf_counter()
    records = []
    for i in range(args.count):
        sid = f"s{i + 1:02d}"
        if args.only and sid not in args.only:
            continue
        t = time.perf_counter()
        record = generate.make(args.seed, i, work / f"seed{args.seed}", cache, say=say)
        records.append(record)
        say(f"[{i + 1}/{args.count}] {sid} generated: {record['class']}, "
            f"{record.get('part', '')} ({time.perf_counter() - t:.0f} s)")
    gen_seconds = time.perf_counter() - start
    say(f"generated {len(records)} scenarios in {gen_seconds:.0f} s")
    if args.generate_only:
        return 0
    scores = {}
    for k, record in enumerate(records, 1):
        if record.get("left_out"):
            continue
        folder = work / f"seed{args.seed}" / record["id"]
        if not (args.resume and (folder / "diagnose.json").is_file()):
            diagnose(folder, say)
        scores[record["id"]] = s = score(record, folder)
        say(f"[{k}/{len(records)}] {record['id']} {record['class']}: {hidden_text(record)} on "
            f"{record['part']} -> {answer_text(s)} ({'right' if s['right'] else 'WRONG'}) "
            f"{s['seconds']:.0f} s, {s['cpu_seconds']:.0f} s CPU, {s['runs']} runs, "
            f"load {s['load'][0]:.1f}" + ("" if s["right"] else f": {s['why']}"))
    command = (f"./drape exec python3 benchmarks/scenarios/run.py --seed {args.seed} "
               f"--count {args.count}")
    text = table(records, scores, command)
    (work / f"seed{args.seed}" / "results.json").write_text(json.dumps(
        {"records": records, "scores": scores, "generate_seconds": gen_seconds,
         "seconds": time.perf_counter() - start}, indent=1, default=str))
    print(text)
    if args.docs:
        write_docs(args.docs, text)
    right = sum(s["right"] for s in scores.values())
    say(f"right {right} of {len(scores)}; {time.perf_counter() - start:.0f} s in all")
    return 0


if __name__ == "__main__":
    sys.exit(main())
