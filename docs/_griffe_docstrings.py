"""A griffe extension for the API pages: the project's docstrings read as they were written.

Two habits of the docstrings that griffe's Google parser and Markdown do not expect are eased
here, before the docstrings are parsed; the source files are not changed.

**reST roles.** ``:class:`History```, ``:func:`~mappers.scores.fold_score``` and the like are
shown as inline code (``History``, ``fold_score``) instead of their raw markup.

**Sections written as prose.** Some docstrings list fitted attributes (or parameters) as running text under a
Google section header, for instance ``Attributes:`` followed by ``embedding_ (M, 2);
stress_ ...`` over several lines at one indentation. griffe's Google parser reads each such
line as an item ``name: description``: it drops the lines without a colon, makes a name of the
words before a colon inside the text, and crashes on a line that starts with a reST role
(``:func:``). This extension rewrites such a section, before it is parsed, as a paragraph headed
by the section's name, so the API pages show the text as written. Sections whose items all have
the ``name (type): description`` form are left to the parser.

Loaded by ``mkdocs.yml`` (``plugins.mkdocstrings.handlers.python.options.extensions``).
"""

from __future__ import annotations

import re
from typing import Any

import griffe

SECTIONS = ("Args", "Arguments", "Parameters", "Attributes", "Raises")
_HEADER = re.compile(r"^(?P<indent>\s*)(?P<name>" + "|".join(SECTIONS) + r"):\s*$")
# an item: one or more names (``a, b``, ``*args``, ``x.y`` for exceptions), an optional
# parenthesised type, then a colon
_ITEM = re.compile(r"^[*\w.]+(, [*\w.]+)*( \([^)]*\))?:(\s|$)")
# a reST role: :func:`target`, :class:`~pkg.mod.Name`, :meth:`title <target>`
_ROLE = re.compile(r":(?:py:)?(?:class|func|meth|mod|data|attr|obj|exc|const):`~?([^`<]*?)(?: <[^`]*>)?`")


def _inline_roles(text: str) -> str:
    """reST roles as inline code; a leading ``~`` keeps only the last dotted name."""

    def code(match: re.Match[str]) -> str:
        target = match[1].strip()
        short = match[0].split("`", 1)[1].startswith("~")
        return f"`{target.rsplit('.', 1)[-1] if short else target}`"

    return _ROLE.sub(code, text)


def _prose_sections(text: str) -> str:
    """``text`` with every section whose items do not all parse rewritten as a paragraph."""
    lines = text.split("\n")
    out: list[str] = []
    i = 0
    while i < len(lines):
        header = _HEADER.match(lines[i])
        if not header:
            out.append(lines[i])
            i += 1
            continue
        j = i + 1
        while j < len(lines) and (not lines[j].strip() or
                                  len(lines[j]) - len(lines[j].lstrip()) > len(header["indent"])):
            j += 1
        body = lines[i + 1:j]
        while body and not body[-1].strip():
            body.pop()
        items = [ln for ln in body if ln.strip()]
        depth = min((len(ln) - len(ln.lstrip()) for ln in items), default=0)
        item_lines = [ln.strip() for ln in items if len(ln) - len(ln.lstrip()) == depth]
        if items and all(_ITEM.match(ln) for ln in item_lines):
            out.extend(lines[i:j])
        else:
            prose = " ".join(ln.strip() for ln in items)
            out.append(f"{header['indent']}**{header['name']}:** {prose}")
            out.extend(lines[i + 1 + len(body):j])
        i = j
    return "\n".join(out)


class ReadableDocstrings(griffe.Extension):
    """Ease the docstrings' reST roles and prose sections (see the module)."""

    def on_object(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None and obj.docstring.value:
            obj.docstring.value = _prose_sections(_inline_roles(obj.docstring.value))
