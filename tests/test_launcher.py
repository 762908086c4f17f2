"""``./drape``: what a call in the image sees of the caller's files.

In the image a command sees only the folders the launcher mounts: the working tree, the
current folder, the paths given as arguments, the absolute paths written in the arguments or
in a script given as one, and ``--mount DIR``. ``DRAPE_SHOW_MOUNTS=1`` prints them and runs
nothing, so the choice is tested anywhere; that the image sees them, and that no empty folder
is left behind to stand for a host folder later, is tested where podman runs (the host).
"""

import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DRAPE = str(ROOT / "drape")
on_the_host = pytest.mark.skipif(
    shutil.which("buildah") is None or Path("/run/.containerenv").exists()
    or os.environ.get("container") is not None,
    reason="runs where ./drape runs the image (the host, with buildah)")


def mounts(*args: str, cwd: Path) -> list[str]:
    env = {**os.environ, "DRAPE_MODE": "container", "DRAPE_SHOW_MOUNTS": "1"}
    done = subprocess.run([DRAPE, *args], cwd=cwd, env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return done.stdout.split()


def test_a_script_sees_the_paths_it_names(tmp_path):
    work, data, extra, out = (tmp_path / n for n in ("work", "data", "extra", "out"))
    for folder in (work, data, extra, out):
        folder.mkdir()
    script = work / "script.py"
    script.write_text(f'open("{data}/bundle.toml")\nopen("/usr/lib/os-release")\n')
    found = mounts("--mount", str(extra), "exec", "python3", str(script), cwd=out)
    # the working tree, the current folder, the script's folder, the path written in it,
    # --mount; never a system folder
    assert {str(ROOT), str(out), str(work), str(data), str(extra)} <= set(found)
    assert not any(m == "/usr" or m.startswith("/usr/") for m in found)
    # A path written in an argument (python3 -c): its nearest existing folder.
    code = f"import os; print(os.listdir('{data}/new/file.csv'))"
    assert str(data) in mounts("exec", "python3", "-c", code, cwd=out)
    assert str(data) not in mounts("exec", "python3", "-c", "print(1)", cwd=out)


def test_mount_needs_a_folder(tmp_path):
    env = {**os.environ, "DRAPE_MODE": "container", "DRAPE_SHOW_MOUNTS": "1"}
    done = subprocess.run([DRAPE, "--mount", str(tmp_path / "none"), "exec", "true"],
                          env=env, capture_output=True, text=True)
    assert done.returncode == 2 and "--mount" in done.stderr and "no such folder" in done.stderr


@on_the_host
def test_in_the_image_a_script_reads_the_callers_file_and_nothing_is_left(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    (data / "x.txt").write_text("measured\n")
    script = tmp_path / "read.py"
    script.write_text(f'print(open("{data}/x.txt").read().strip())\n')
    env = {**os.environ, "DRAPE_MODE": "container"}
    done = subprocess.run([DRAPE, "exec", "python3", str(script)], cwd=ROOT, env=env,
                          capture_output=True, text=True)
    assert done.returncode == 0 and done.stdout.strip() == "measured", done.stderr
    # A later call that does not name the folder finds no empty folder in its place.
    hidden = "import os, sys; p = sys.argv[1][::-1]; print(os.path.exists(p))"
    done = subprocess.run([DRAPE, "exec", "python3", "-c", hidden, str(data)[::-1]], cwd=ROOT,
                          env=env, capture_output=True, text=True)
    assert done.returncode == 0 and done.stdout.strip() == "False", done.stderr


@on_the_host
def test_in_the_image_the_runs_go_to_the_hosts_cache_folder():
    """The default run cache is the documented one on the host, or DRAPE_CACHE when set."""
    state = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "fenicsx-drape"
    code = ("from fenicsx_drape.runs.store import default_folder; "
            "print(default_folder())")
    env = {k: v for k, v in os.environ.items() if k != "DRAPE_CACHE"}
    env["DRAPE_MODE"] = "container"
    done = subprocess.run([DRAPE, "exec", "python3", "-c", code], cwd=ROOT, env=env,
                          capture_output=True, text=True)
    assert done.returncode == 0 and done.stdout.strip() == str(state / "runs"), done.stderr
    env["DRAPE_CACHE"] = "off"
    done = subprocess.run([DRAPE, "exec", "python3", "-c", code], cwd=ROOT, env=env,
                          capture_output=True, text=True)
    assert done.returncode == 0 and done.stdout.strip() == "None", done.stderr
