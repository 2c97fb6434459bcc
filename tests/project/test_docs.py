"""The README and docs/: every local link resolves, every command names a real subcommand and files."""

import re
from pathlib import Path

import pytest

from orchestrator.cli import parser as build_parser

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
_LINK = re.compile(r"\]\(([^)\s]+)\)")
_TAPMP = re.compile(r"\.venv/bin/tapmp ([\w-]+)((?: [^\s`|]+)*)")


def _anchors(page: Path) -> set:
    """GitHub's anchors of a page's headings: lower case, punctuation dropped, spaces to '-'."""
    out = set()
    for line in page.read_text().splitlines():
        if line.startswith("#"):
            text = line.lstrip("#").strip().lower()
            out.add(re.sub(r"[^\w\- ]", "", text).replace(" ", "-"))
    return out


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_local_link_resolves_to_a_file_and_heading(page):
    for target in _LINK.findall(page.read_text()):
        if re.match(r"[a-z]+:", target):
            continue  # http(s), mailto
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        assert dest.exists(), f"{page.name}: link to {target} points to nothing"
        if anchor and dest.suffix == ".md":
            assert anchor in _anchors(dest), f"{page.name}: link {target}: no such heading in {dest.name}"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_tapmp_command_is_a_real_subcommand_on_existing_files(page):
    subcommands = set(build_parser()._subparsers._group_actions[0].choices)
    for sub, args in _TAPMP.findall(page.read_text()):
        assert sub in subcommands, f"{page.name}: '.venv/bin/tapmp {sub}' is no subcommand"
        for arg in args.split():
            if re.fullmatch(r"(scenarios|studies)/[\w.-]+\.toml", arg):
                assert (ROOT / arg).is_file(), f"{page.name}: {arg} does not exist"
