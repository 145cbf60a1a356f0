"""One report, two renderings: Markdown and one self-contained HTML page, from the same list of blocks.

blocks: ("h", level, text) ("p", text) ("ul", [text]) ("kv", [(key, value)]) ("warn", [text])
        ("table", head, rows) ("code", lang, text) ("fig", title, file name)
"""

from __future__ import annotations

import base64
import html
import re
from collections.abc import Sequence


def md_table(head: list[str], rows: list[list[str]], align: list[str] | None = None) -> str:
    def cell(s: str) -> str:
        return s.replace("|", "\\|").replace("\n", " ")

    align = align or ["---"] * len(head)
    out = ["| " + " | ".join(cell(h) for h in head) + " |", "|" + "|".join(align) + "|"]
    out += ["| " + " | ".join(cell(c) for c in r) + " |" for r in rows]
    return "\n".join(out)

def render_markdown(blocks: Sequence[tuple]) -> str:
    out: list[str] = []
    for blk in blocks:
        kind = blk[0]
        if kind == "h":
            out += ["#" * blk[1] + " " + blk[2], ""]
        elif kind == "p":
            out += [blk[1], ""]
        elif kind in ("ul", "warn"):
            out += [f"- {t}" for t in blk[1]] + [""]
        elif kind == "kv":
            out += [f"- **{k}**: {v if k != 'command' else '`' + v + '`'}" for k, v in blk[1]] + [""]
        elif kind == "table":
            head, rows = blk[1], blk[2]
            align = ["---:", "---", "---"] + ["---:"] * (len(head) - 4) + ["---"] if head[0] == "rank" else None
            out += [md_table(head, rows, align), ""]
        elif kind == "code":
            out += [f"```{blk[1]}", blk[2], "```", ""]
        elif kind == "fig":
            out += [f"### {blk[1]}", "", f"![{blk[1]}]({blk[2]})", ""]
    return "\n".join(out)


def _inline(text: str) -> str:
    """The markdown inline marks used in the blocks (`code`, **bold**, *em*) as HTML, escaped."""
    parts = re.split(r"(`[^`]*`)", text)
    out = []
    for p in parts:
        if p.startswith("`") and p.endswith("`") and len(p) >= 2:
            out.append(f"<code>{html.escape(p[1:-1])}</code>")
        else:
            s = html.escape(p, quote=False)
            s = re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", s)
            s = re.sub(r"(?<![\w*])\*(?!\s)(.+?)(?<!\s)\*(?![\w*])", r"<em>\1</em>", s)
            out.append(s)
    return "".join(out)


CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;margin:1.5em auto;max-width:1500px;padding:0 1em;
color:#222;line-height:1.4}
h1{font-size:1.5em;margin-bottom:.3em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:1.6em}
h3{font-size:1.05em}
table{border-collapse:collapse;font-size:.85em;margin:.5em 0}
th,td{border:1px solid #ccc;padding:.25em .5em;text-align:right;vertical-align:top}
th{background:#f0f0f0}td:nth-child(2),td:nth-child(3),td.note{text-align:left}td.note{font-style:italic}
table.kv th{text-align:left;width:9em}table.kv td{text-align:left;font-family:monospace;word-break:break-all}
.scroll{overflow-x:auto}
.warn{background:#fff6d6;border:1px solid #e0c060;border-radius:4px;padding:.4em 1em}
.warn li{margin:.2em 0}
figure{margin:1em 0}figure img{max-width:100%;height:auto;border:1px solid #ddd}
figcaption{font-weight:bold;margin-bottom:.3em}
pre{background:#f7f7f7;border:1px solid #ddd;padding:.5em;overflow-x:auto;font-size:.8em;max-height:30em}
code{background:#f3f3f3;padding:0 .2em}
details{margin:.3em 0 1em}summary{cursor:pointer}
"""


def _html_table(head: list[str], rows: list[list[str]]) -> str:
    """A table; in the results table (last column *note*) a failed or skipped estimator's note spans
    the figures it does not have."""
    noted = head[-1] == "note"
    cols = head[:-1] if noted else head
    out = []
    for r in rows:
        if noted and r[-1]:
            out.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r[:3])
                       + f'<td class="note" colspan="{len(cols) - 3}">{html.escape(r[-1])}</td></tr>')
        else:
            out.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in (r[:-1] if noted else r)) + "</tr>")
    th = "".join(f"<th>{html.escape(h)}</th>" for h in cols)
    return (f'<div class="scroll"><table class="results"><thead><tr>{th}</tr></thead>'
            f"<tbody>{''.join(out)}</tbody></table></div>")


def render_html(blocks: Sequence[tuple], images: dict[str, bytes]) -> str:
    """One self-contained page: inline CSS, figures as ``data:image/png;base64`` URIs, no script; the
    Content-Security-Policy forbids loading anything from anywhere else."""
    title = next((b[2] for b in blocks if b[0] == "h" and b[1] == 1), "graphnav report")
    body: list[str] = []
    for blk in blocks:
        kind = blk[0]
        if kind == "h":
            body.append(f"<h{blk[1]}>{_inline(blk[2])}</h{blk[1]}>")
        elif kind == "p":
            body.append(f"<p>{_inline(blk[1])}</p>")
        elif kind == "ul":
            body.append("<ul>" + "".join(f"<li>{_inline(t)}</li>" for t in blk[1]) + "</ul>")
        elif kind == "warn":
            body.append('<div class="warn"><ul>' + "".join(f"<li>{_inline(t)}</li>" for t in blk[1]) + "</ul></div>")
        elif kind == "kv":
            rows = "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(v)}</td></tr>" for k, v in blk[1])
            body.append(f'<table class="kv">{rows}</table>')
        elif kind == "table":
            body.append(_html_table(blk[1], blk[2]))
        elif kind == "code":
            body.append(f"<details><summary>{html.escape(blk[1])}</summary><pre>{html.escape(blk[2])}</pre></details>")
        elif kind == "fig":
            data = images.get(blk[2])
            if data is None:
                continue
            uri = "data:image/png;base64," + base64.b64encode(data).decode("ascii")
            body.append(f'<figure id="{html.escape(blk[2])}"><figcaption>{_inline(blk[1])}</figcaption>'
                        f'<img src="{uri}" alt="{html.escape(blk[1])}"></figure>')
    csp = "default-src 'none'; img-src data:; style-src 'unsafe-inline'"
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f'<meta http-equiv="Content-Security-Policy" content="{csp}">'
            '<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>{html.escape(title)}</title><style>{CSS}</style></head>\n<body>\n"
            + "\n".join(body) + "\n</body></html>\n")

