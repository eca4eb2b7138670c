"""Griffe extension for the docs build: Sphinx roles in docstrings rendered as code.

The docstrings use reStructuredText roles (:class:`~slam_lcd.types.Keyframe`, :func:`x`);
MkDocs renders Markdown, where those would show as ``:class:Keyframe``. This turns each role
into inline code of its target's last name (``~`` dropped), before mkdocstrings renders.
"""
from __future__ import annotations

import re

import griffe

_ROLE = re.compile(r":(?:py:)?(?:class|func|meth|attr|mod|data|obj|exc|const|ref):`~?([^`]+)`")


def _code(match: re.Match) -> str:
    target = match.group(1)
    if "<" in target and target.endswith(">"):  # :ref:`text <target>`
        target = target.split("<", 1)[0].strip()
    return f"`{target.rsplit('.', 1)[-1] if match.group(0).find('~') >= 0 else target}`"


class RstRoles(griffe.Extension):
    """Rewrite Sphinx roles in every docstring griffe loads."""

    def on_instance(self, *, obj, **kwargs) -> None:
        if obj.docstring is not None:
            obj.docstring.value = _ROLE.sub(_code, obj.docstring.value)
