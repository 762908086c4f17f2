"""The docs state what is true now: links resolve, the contract version is the code's, the
numbers the README quotes from its diagnosis loop are what the loop gives, and every demo page
shows its pictures or says why the site does not run it.

Each kind of drift that can be checked has a test here; that the command lines the docs show
are real is :mod:`test_docs_commands`.
"""

import json
import re
import shlex
from pathlib import Path

import pytest

from fenicsx_drape.cli import main
from fenicsx_drape.diagnosis.report import CONTRACT

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def links(page: Path) -> list[tuple[str, str]]:
    """The relative link targets of a Markdown page, each with ``page:line``."""
    found = []
    for number, line in enumerate(page.read_text().splitlines(), start=1):
        for target in LINK.findall(line):
            if not re.match(r"^[a-z]+:", target) and not target.startswith("#"):
                found.append((target.split("#")[0], f"{page.relative_to(ROOT)}:{number}"))
    return found


LINKS = [link for page in PAGES for link in links(page)]


def test_pages_link_to_files():
    assert len(LINKS) >= 20 and any(w.startswith("README") for _, w in LINKS)


@pytest.mark.parametrize(("target", "where"), LINKS, ids=[w for _, w in LINKS])
def test_link_exists(target, where):
    page = ROOT / where.split(":")[0]
    path = (page.parent / target).resolve()
    assert path.exists(), f"{where}: {target} does not exist"
    assert path.is_relative_to(ROOT), f"{where}: {target} is outside the repository"


def test_no_page_names_a_path_outside_the_repository():
    for page in PAGES:
        for number, line in enumerate(page.read_text().splitlines(), start=1):
            assert "shared/spec" not in line and "/work/" not in line, \
                f"{page.relative_to(ROOT)}:{number}: a path outside the repository"


def test_the_docs_quote_the_contract_version_of_the_code():
    quoted = [(int(n), page.name) for page in PAGES
              for n in re.findall(r'"contract":\s*(\d+)', page.read_text())]
    assert len(quoted) >= 2  # diagnosis.md and measurements.md
    assert all(n == CONTRACT for n, _ in quoted), quoted


def test_one_version_number_for_the_spec_in_the_code_the_report_and_the_pages():
    """The spec's version (its title) is the report's ``contract``; a page that names the
    spec's version names that one."""
    title = (ROOT / "docs" / "measurements.md").read_text().splitlines()[0]
    assert re.fullmatch(r"# .*\(version (\d+)\)", title), title
    assert int(re.findall(r"\d+", title)[-1]) == CONTRACT
    for page in PAGES:
        for number, line in enumerate(page.read_text().splitlines(), start=1):
            for n in re.findall(r"spec,? version (\d+)", line):
                assert int(n) == CONTRACT, f"{page.relative_to(ROOT)}:{number}: version {n}"


def readme_loop() -> list[list[str]]:
    """The README's diagnosis loop: the code block after "The loop:", as argument lists."""
    text = (ROOT / "README.md").read_text()
    block = text[text.index("The loop:"):].split("```sh\n", 1)[1].split("```", 1)[0]
    commands = block.replace("\\\n", " ").splitlines()
    return [shlex.split(c)[1:] for c in commands if c.startswith("./drape ")]


def test_the_diagnosis_page_shows_the_readme_loop():
    text = (ROOT / "docs" / "diagnosis.md").read_text()
    block = text.split("```sh\n", 1)[1].split("```", 1)[0]
    commands = block.replace("\\\n", " ").splitlines()
    assert [shlex.split(c)[1:] for c in commands if c.startswith("./drape ")] == readme_loop()


def test_the_readme_loop_adds_exactly_one_effect():
    from fenicsx_drape.model import load_model

    models = [c[c.index("--model") + 1] for c in readme_loop() if c[0] == "compare"]
    assert len(models) == 2
    before, after = (set(load_model(ROOT / m).effects) for m in models)
    diagnosed = {c[c.index("--model") + 1] for c in readme_loop() if c[0] == "diagnose"}
    assert diagnosed == {models[0]}
    assert after - before == {"rate_dependence"} and before <= after


@pytest.mark.slow
def test_the_readme_loop_gives_the_numbers_it_quotes(tmp_path, monkeypatch, capsys):
    """The README's four commands, run as written (outputs in a temporary folder)."""
    monkeypatch.chdir(ROOT)
    for args in readme_loop():
        args = [str(tmp_path / a) if a.startswith("results/") else a for a in args]
        assert main([*args, "--quiet"] if args[0] == "diagnose" else args) == 0, args
    report = json.loads((tmp_path / "results/diagnosis/REPORT.json").read_text())
    history = capsys.readouterr().out
    readme = (ROOT / "README.md").read_text()
    said = re.search(r"`diagnose` names `(\w+)` \(normalised error ([\d.]+) → ([\d.]+), "
                     r"evidence ([\d.]+)\)", " ".join(readme.split()))
    effect, before, after, evidence = said.groups()
    best = report["candidates"][0]
    assert report["missing_effect"] == effect == best["effect"]
    assert f"{report['baseline']['error']['normalised']:.2f}" == before
    assert f"{best['error_after']['normalised']:.2f}" == after
    assert f"{best['evidence']:.1f}" == evidence
    # history: v1 -> v2 adds the one effect, at the errors quoted
    v2 = [line for line in history.splitlines() if line.startswith("v2 ")]
    assert v2 and f"+{effect} " in v2[0] and f" {after} " in v2[0] and "," not in v2[0]
    # docs/diagnosis.md's table and the getting-started page quote the same run
    table = (ROOT / "docs" / "diagnosis.md").read_text()
    assert f"evidence {evidence};" in table and f"| {after} | — |" in table
    start = " ".join((ROOT / "docs" / "getting-started.md").read_text().split())
    assert f"error {before} → {after}, evidence {evidence}" in start


def demo_pages() -> tuple[list[Path], set[str]]:
    """The demos the site renders as pages, and those ``docs/conf.py`` does not execute."""
    conf = (ROOT / "docs" / "conf.py").read_text()
    excluded = conf[conf.index("nb_execution_excludepatterns"):].split("]", 1)[0]
    names = set(re.findall(r'"demos/([\w.]+\.py)"', excluded))
    pages = [*sorted((ROOT / "demos").glob("demo_*.py")), ROOT / "demos/tutorial_own_part.py"]
    return pages, names


def test_every_demo_page_shows_its_pictures_or_says_why_it_is_not_run():
    pages, not_run = demo_pages()
    assert not_run and not_run <= {p.name for p in pages}
    for page in pages:
        text = page.read_text()
        if page.name in not_run:  # said under the title, before the first code
            head = text[text.index("\n# # "):].split("\n\n", 1)[0]
            assert "**Not run on this site**" in head, f"{page.name}: not run, and not said why"
        elif ".png" in text:  # it draws pictures: the page shows them
            assert "display(Image(" in text, f"{page.name}: its pictures are not shown"
