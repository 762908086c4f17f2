"""The ledger of model versions and their errors (``drape history``).

Every ``drape compare --out DIR`` appends one line to ``DIR/ledger.jsonl``: when, which bundle,
which model (effects, plugins, fitted parameters) and its errors. :func:`history` gathers the
ledgers of several folders (or of one folder compared into repeatedly), orders the versions in
time, says what changed from one version to the next, and plots the normalised error version
by version against the noise floor. ``drape diagnose --out DIR`` records the versions a
diagnosis went through (:func:`record_history`: the set-up as stated, the set-up fitted, the
effect added).
"""

from __future__ import annotations

import dataclasses
import datetime
import hashlib
import json
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.provenance import json_text

if TYPE_CHECKING:
    from fenicsx_drape.measurements.bundle import Bundle

LEDGER = "ledger.jsonl"


class Compared(Protocol):
    """What the ledger records of a comparison (a ``compare.CompareResult``).

    A protocol rather than the class itself: compare writes into the ledger, so the ledger
    must not import compare back.
    """

    bundle: str  # the bundle's name

    def to_dict(self) -> dict[str, Any]:
        """The content of ``compare.json`` (``model``, ``error``, ``noise_floor``, ...)."""
        ...


def record(out_dir: str | Path, result: Compared, *, bundle: Bundle,
           model_path: str | Path | None = None) -> dict[str, Any]:
    """Append the version compared in ``result`` to ``out_dir/ledger.jsonl``; returns it."""
    record = result.to_dict()
    return record_version(out_dir, result.bundle, record["model"], record["error"],
                          record["noise_floor"], bundle=bundle, model_path=model_path)


def record_version(out_dir: str | Path, bundle_name: str, model: dict[str, Any],
                   error: dict[str, Any], noise_floor: dict[str, Any], *,
                   bundle: Bundle | None = None, model_path: str | Path | None = None,
                   setup: dict[str, Any] | None = None) -> dict[str, Any]:
    """Append one model version to ``out_dir/ledger.jsonl``; returns the entry.

    ``model`` has ``effects`` (and ``plugins``, ``parameters``); ``error`` and
    ``noise_floor`` are the contract's records. ``setup``: the process set-up fitted with
    this version (parameter: value; a diagnosis's set-up stage), shown as a change like an
    effect.
    """
    entry = {
        "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="microseconds"),
        "dir": str(Path(out_dir).resolve()),
        "bundle": bundle_name,
        "bundle_path": str(Path(bundle.path).resolve()) if bundle and bundle.path else None,
        "model_path": str(Path(model_path).resolve()) if model_path else None,
        **model,
        "normalised": error["normalised"],
        "rmse": error["rmse_N"],
        "noise_rmse": noise_floor["rmse_N"],
        "per_test": error["per_test"],
        "noise_per_test": noise_floor["per_test"],
    }
    if setup:
        entry["setup"] = setup
    entry["id"] = hashlib.sha1(json_text(entry, indent=None, sort_keys=True).encode()
                               ).hexdigest()[:12]
    path = Path(out_dir) / LEDGER
    path.parent.mkdir(parents=True, exist_ok=True)
    # One short line appended in one write: concurrent appenders do not interleave.
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        os.write(fd, (json_text(entry, indent=None, sort_keys=True) + "\n").encode())
    finally:
        os.close(fd)
    return entry


def read(dirs: Iterable[str | Path]) -> list[dict[str, Any]]:
    """The ledger entries of the folders, each once, oldest first.

    Raises:
        DrapeInputError: for a folder without ``ledger.jsonl``, or a line that is not a
            ledger entry (naming the file and line).
    """
    entries: dict[str, dict[str, Any]] = {}
    for folder in dirs:
        path = Path(folder) / LEDGER
        if not path.is_file():
            raise DrapeInputError(f"{folder}: no {LEDGER} here (run 'drape compare BUNDLE "
                                  f"--out {folder}' first)")
        for number, line in enumerate(path.read_text().splitlines(), start=1):
            if not line.strip():
                continue
            try:
                entry = json.loads(line)
                entry["id"], entry["created"], entry["normalised"], entry["effects"]
            except (json.JSONDecodeError, KeyError, TypeError) as err:
                raise DrapeInputError(f"{path}:{number}: not a ledger entry ({err})") from None
            entries.setdefault(entry["id"], entry)
    return sorted(entries.values(), key=lambda e: (e["created"], e["id"]))


@dataclasses.dataclass(frozen=True)
class Version:
    """One model version in the history."""

    label: str  # "v1", "v2", ... in time order
    change: str  # what changed from the previous version (effects, plugins, bundle)
    entry: dict[str, Any]  # the ledger entry


def versions(entries: Sequence[dict[str, Any]]) -> list[Version]:
    """Label the entries (oldest first) version by version, with what changed."""
    out: list[Version] = []
    previous = None
    for k, entry in enumerate(entries, start=1):
        out.append(Version(f"v{k}", _change(previous, entry), entry))
        previous = entry
    return out


def _change(previous: dict[str, Any] | None, entry: dict[str, Any]) -> str:
    if previous is None:
        return "first version"
    before, after = set(previous["effects"]), set(entry["effects"])
    parts = [f"+{e}" for e in sorted(after - before)] + [f"-{e}" for e in sorted(before - after)]
    before_setup, setup = previous.get("setup") or {}, entry.get("setup") or {}
    parts += [f"setup {k} = {_value(v)}" for k, v in setup.items() if before_setup.get(k) != v]
    parts += [f"setup {k} as stated" for k in before_setup if k not in setup]
    new_plugins = sorted(set(entry.get("plugins", [])) - set(previous.get("plugins", [])))
    parts += [f"plugin {Path(p).name}" for p in new_plugins]
    if entry["bundle"] != previous["bundle"]:
        parts.append(f"bundle {entry['bundle']}")
    return ", ".join(parts) if parts else "same model (refit)"


def _value(v) -> str:
    return f"[{v[0]:.3g}, {v[1]:.3g}]" if isinstance(v, list) else f"{v:.4g}"


def history_table(history: Sequence[Version]) -> str:
    """The history as a text table."""
    rows = [("version", "bundle", "normalised", "rmse", "noise", "change", "folder")]
    for v in history:
        e = v.entry
        rows.append((v.label, e["bundle"], f"{e['normalised']:.3g}", f"{e['rmse']:.3g}",
                     f"{e['noise_rmse']:.3g}", v.change, e["dir"]))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


table = history_table  # the earlier name, kept for one release


def plot(history: Sequence[Version], path: str | Path) -> Path:
    """``history.png``: normalised error version by version, the noise floor at 1."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import LogFormatter

    from fenicsx_drape.provenance import save_figure

    fig, ax = plt.subplots(figsize=(max(6.0, 1.3 * len(history)), 4.5))
    errors = [v.entry["normalised"] for v in history]
    bundles = list(dict.fromkeys(v.entry["bundle"] for v in history))
    for i, name in enumerate(bundles):
        points = [(k, v.entry["normalised"]) for k, v in enumerate(history)
                  if v.entry["bundle"] == name]
        ax.plot(*zip(*points), "o-", color=f"C{i}", label=f"bundle {name}")
    for k, error in enumerate(errors):
        ax.annotate(f"{error:.2f}", (k, error), textcoords="offset points", xytext=(0, 7),
                    ha="center", fontsize=8)
    ax.axhline(1.0, color="k", ls="--", lw=1, label="noise floor")
    ax.axhline(1.5, color="0.5", ls=":", lw=1, label="adequate (1.5 × noise)")
    ax.set_yscale("log")
    ax.yaxis.set_major_formatter(LogFormatter(labelOnlyBase=False))
    ax.yaxis.set_minor_formatter(LogFormatter(labelOnlyBase=False))
    ax.set_xticks(range(len(history)),
                  [f"{v.label}\n{v.change}".replace(", ", "\n") for v in history], fontsize=7)
    ax.set_ylabel("normalised error (RMSE / noise)")
    ax.set_title("model versions")
    ax.legend(fontsize=8)
    return save_figure(fig, path)


def history(dirs: Iterable[str | Path], out_dir: str | Path | None = None) -> list[Version]:
    """The versions recorded in the ledgers of ``dirs``, oldest first.

    With ``out_dir``, also writes ``history.png``, ``history.json`` and ``provenance.json``
    there.
    """
    dirs = list(dirs)
    result = versions(read(dirs))
    if out_dir is not None:
        from fenicsx_drape.provenance import write_json, write_provenance

        out = Path(out_dir)
        plot(result, out / "history.png")
        write_json(out / "history.json", [{"version": v.label, "change": v.change, **v.entry}
                                          for v in result])
        write_provenance(out, ledgers=[str(Path(d).resolve()) for d in dirs])
    return result


def record_history(report: dict[str, Any], out_dir, bundle: Bundle | None = None) -> list[dict]:
    """Record a diagnosis's model versions in ``out_dir``'s ledger (``drape history``).

    In order: the model with the set-up as stated (when set-up candidates were tried), with
    the set-up error fitted, and with the missing effect added: the error falls version by
    version as the set-up is corrected, then as the effect is added.
    """
    if "error" not in report.get("baseline", {}) or "noise_floor" not in report:
        return []
    base = report["baseline"]
    model = {k: base[k] for k in ("effects", "plugins", "parameters") if k in base}
    noise = report["noise_floor"]
    name = report.get("bundle", bundle.name if bundle else "")
    entries = []
    setup = None
    if report.get("setup"):
        stated = report["setup_stated"]["error"]
        entries.append(record_version(out_dir, name, model, stated, noise, bundle=bundle))
        if report.get("setup_error"):
            best = report["setup"][0]
            setup = {best["parameter"]: best["fitted"]}
    if setup or not entries:
        entries.append(record_version(out_dir, name, model, base["error"], noise,
                                      bundle=bundle, setup=setup))
    if report.get("missing_effect"):
        c = report["candidates"][0]
        added = {**model, "effects": list(dict.fromkeys([*model.get("effects", []),
                                                         *c["effects"]]))}
        entries.append(record_version(out_dir, name, added, c["error_after"], noise,
                                      bundle=bundle, setup=setup))
    return entries
