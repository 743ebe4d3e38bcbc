"""docs/scenarios.md as the tests of the page read it: its text, its sections by heading and their table rows."""

import re
from pathlib import Path

ROOT = Path(__file__).parents[1]
DOC_PATH = ROOT / "docs" / "scenarios.md"
DOC = DOC_PATH.read_text()


def _sections():
    """``{heading text: body}`` of every heading (any level), code blocks skipped for headings."""
    out, head, body, fenced = {}, None, [], False
    for line in DOC.splitlines():
        if line.startswith("```"):
            fenced = not fenced
        m = None if fenced else re.match(r"#{1,6} (.*)", line)
        if m:
            if head is not None:
                out[head] = "\n".join(body)
            head, body = m.group(1).strip(), []
        else:
            body.append(line)
    out[head] = "\n".join(body)
    return out


SECTIONS = _sections()


def _rows(body):
    """``{key: [cells after the key]}`` of the table rows whose first cell is a backquoted name."""
    rows = {}
    for line in body.splitlines():
        m = re.match(r"\| `([^`]+)`[^|]*\|(.*)\|\s*$", line)
        if m:
            rows[m.group(1)] = [c.strip() for c in m.group(2).split("|")]
    return rows
