"""Report pages as HTML: a scenario's ``report.md`` rendered as ``report.html`` beside it, and the page frame the
overview shares (one self-contained page: the style inline, figures linked relatively, no network, no JavaScript).
"""

from __future__ import annotations

import html
from pathlib import Path

import markdown

from fusionbench.files.imufiles import atomic_open

#: The style of every report page.
CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",sans-serif;margin:2em auto;max-width:80em;padding:0 1em;
color:#222;line-height:1.4}
table{border-collapse:collapse;margin:1em 0;font-size:0.9em}
th,td{border:1px solid #ccc;padding:0.3em 0.5em;text-align:right;vertical-align:top}
th{background:#f3f3f3;font-size:0.85em}
td:first-child,th:first-child{text-align:left;white-space:nowrap}
.good{background:#d9f0d3}.fair{background:#fdf1c7}.poor{background:#f6d0cc}.none{color:#999}
.scroll{overflow-x:auto}
img{max-width:100%}
.thumb{max-width:28em;border:1px solid #ddd}
code{background:#f5f5f5;padding:0 0.2em}
small{color:#555}
"""


def page(title, body):
    """A self-contained HTML page (no network, no JavaScript) of ``title`` and the HTML ``body``."""
    return (f'<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">\n<title>{html.escape(title)}</title>\n'
            f"<style>{CSS}</style>\n</head>\n<body>\n{body}\n</body>\n</html>\n")


def write_page(report_md):
    """Render a scenario's ``report.md`` as ``report.html`` beside it (same relative figure links); returns its path."""
    report_md = Path(report_md)
    text = report_md.read_text(encoding="utf-8")
    body = markdown.markdown(text, extensions=["tables", "fenced_code"], output_format="html")
    title = text.splitlines()[0].lstrip("# ").strip() if text else report_md.parent.name
    nav = '<p><a href="../index.html">overview</a> · <a href="report.md">report.md</a> · ' \
          '<a href="metrics.json">metrics.json</a></p>\n'
    path = report_md.with_suffix(".html")
    with atomic_open(path) as fh:
        fh.write(page(title, nav + body))
    return path
