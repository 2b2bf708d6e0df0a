"""The report's output (report/make_report.py): the output folder checked, one document
written as HTML (plots inline as SVG) and Markdown (plots as plots/*.svg), every file
renamed into place only once all are written."""

import html
import io
import json
import os
import re
import stat
import tempfile

from report_common import MAX_LINE, bounded, fail, plt


def output_dir(path, option):
    """Exit 2 naming `option` unless `path` is a writable folder or can be made one: not a
    file, a device, a symbolic link (e.g. to /etc) or a read-only folder."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        parent = os.path.dirname(os.path.abspath(path))
        while not os.path.exists(parent):
            parent = os.path.dirname(parent)
        if not os.path.isdir(parent) or not os.access(parent, os.W_OK) or not os.stat(parent).st_mode & 0o222:
            fail(f"{option} {path}: cannot be created in {parent} (not a writable folder); allowed: a folder octocd "
                 "may write in")
        return
    if stat.S_ISLNK(st.st_mode):
        fail(f"{option} {path}: a symbolic link (to {os.readlink(path)}); allowed: a folder path that is not a link")
    if not stat.S_ISDIR(st.st_mode):
        kind = "a FIFO" if stat.S_ISFIFO(st.st_mode) else "a device" \
            if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode) else "a file"
        fail(f"{option} {path}: {kind}, not a folder; allowed: a folder (created when missing)")
    if not os.access(path, os.W_OK) or not st.st_mode & 0o222:
        fail(f"{option} {path}: a read-only folder; allowed: a folder octocd may write in")


def current_umask():
    """The process's umask without changing it (/proc/self/status; 0o022 when unknown)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except OSError:
        pass
    return 0o022


def refuse_non_regular(path):
    """A report file's path must be absent or a regular file: a link, FIFO, device or folder
    planted at it is refused (exit 2), never replaced or written through."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return
    if stat.S_ISREG(st.st_mode):
        return
    kind = "a symbolic link" if stat.S_ISLNK(st.st_mode) else "a FIFO" if stat.S_ISFIFO(st.st_mode) \
        else "a folder" if stat.S_ISDIR(st.st_mode) else "a device" \
        if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode) else "not a plain file"
    fail(f"{path}: {kind}, not a regular file; allowed: a new file or a regular file (replaced by rename)")


_MD_SPECIAL = re.compile(r"[\\`*_\[\]|]|<(?=[A-Za-z/!?])|^\s*[#>+-]")
_MD_SPECIAL_CELL = re.compile(r"[\\`*_\[\]|]|<(?=[A-Za-z/!?])")
# A cell's text holding none of these is its own Markdown (md_escape's fast path: a report
# of 10^5 points has 10^6 cells).
_MD_CELL_ANY = re.compile(r"[\\`*_\[\]|<\r\n]")
# Text holding none of these is its own HTML (html.escape changes only these).
_HTML_SPECIAL = re.compile(r"[&<>\"']")


def md_escape(text, cell=False):
    """`text` as literal Markdown: its characters that make markup escaped with a backslash
    (backslash, backtick, *, _, brackets, |; < before a tag or an autolink; #, >, +, - that
    would start a heading, quote or list) and line breaks made spaces, so that an engine's,
    a scene's or a file's name from a bench result or a trace cannot add links, images,
    HTML, headings or table cells to report.md. `cell`: a table cell's text, which starts
    no line (a leading #, >, +, - stays as it is)."""
    if cell and type(text) is str and len(text) <= MAX_LINE and not _MD_CELL_ANY.search(text):
        return text
    flat = bounded(text, MAX_LINE).replace("\r", " ").replace("\n", " ")
    return (_MD_SPECIAL_CELL if cell else _MD_SPECIAL).sub(lambda m: m.group(0)[:-1] + "\\" + m.group(0)[-1], flat)


def html_text(text):
    """`text` for HTML: bounded (report_common.bounded, MAX_LINE) and escaped (no tag,
    attribute or entity from data)."""
    if type(text) is str and len(text) <= MAX_LINE and not _HTML_SPECIAL.search(text):
        return text
    return html.escape(bounded(text, MAX_LINE))


class Outputs:
    """Every file of one report, kept in memory until commit(): then each is written to a
    temporary file beside its destination, and only when all are written are they renamed
    into place (a full disk or a size limit leaves the earlier report as it was)."""

    def __init__(self):
        self.files = {}  # path -> text

    def put(self, path, text):
        self.files[path] = text

    def commit(self):
        temps = []
        made = []  # folders this commit created: removed again (when empty) if it fails
        try:
            for path, text in self.files.items():
                folder = os.path.dirname(path) or "."
                missing = []
                while folder and not os.path.exists(folder):
                    missing.append(folder)
                    folder = os.path.dirname(folder)
                os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
                made += missing
                refuse_non_regular(path)
                # An unpredictable name created O_EXCL (mkstemp): a link planted at a
                # temporary name is never followed.
                fd, tmp = tempfile.mkstemp(dir=os.path.dirname(path) or ".", prefix=f".{os.path.basename(path)}.tmp.")
                temps.append((tmp, path))
                os.fchmod(fd, 0o666 & ~current_umask())
                with os.fdopen(fd, "w", newline="") as f:
                    f.write(text)
                    f.flush()
                    os.fsync(f.fileno())
            for tmp, path in temps:
                refuse_non_regular(path)
                os.replace(tmp, path)
        except BaseException:
            for tmp, _ in temps:
                try:
                    os.unlink(tmp)
                except OSError:
                    pass
            for folder in made:  # deepest first: a failed report leaves no empty plots/ folder
                try:
                    os.rmdir(folder)
                except OSError:
                    pass
            raise


class Doc:
    """One report, written both as HTML and as Markdown (files committed by write())."""

    def __init__(self, out, csv_dir=None):
        self.out = out
        self.html, self.md = [], []
        self.nplot = 0
        self.ncsv = 0
        self.section = "report"
        self.csv_dir = csv_dir
        self.files = Outputs()

    def h(self, level, text, anchor=None):
        a = f' id="{anchor}"' if anchor else ""
        self.html.append(f"<h{level}{a}>{html_text(text)}</h{level}>")
        self.md.append("#" * level + " " + md_escape(text) + "\n")

    def p(self, text, cls=None):
        c = f' class="{cls}"' if cls else ""
        self.html.append(f"<p{c}>{html_text(text)}</p>")
        self.md.append(md_escape(text) + "\n")

    def table(self, header, rows, note=None, name="table"):
        cls = ' class="compact"' if len(header) > 9 else ""
        t = [f'<div class="wide"><table{cls}><thead><tr>' + "".join(f"<th>{html_text(x)}</th>" for x in header) + "</tr></thead><tbody>"]
        for r in rows:
            t.append("<tr>" + "".join(f"<td>{html_text(x)}</td>" for x in r) + "</tr>")
        t.append("</tbody></table></div>")
        self.html.append("".join(t))
        self.md.append("| " + " | ".join(md_escape(x, cell=True) for x in header) + " |")
        self.md.append("|" + "|".join("---" for _ in header) + "|")
        for r in rows:
            self.md.append("| " + " | ".join(md_escape(x, cell=True) for x in r) + " |")
        self.md.append("")
        if note:
            self.p(note, "note")

    def figure(self, fig, name, caption):
        self.nplot += 1
        fname = f"{self.nplot:02d}-{name}.svg"
        buf = io.StringIO()
        # The engines on the plot (report_plots.note_engine: each one's colour and marker, or why
        # it is not drawn) as the SVG's dc:description, "octocd-engines {json}", for tests.
        engines = getattr(fig, "octocd_engines", None)
        meta = {"Description": "octocd-engines " + json.dumps(engines, sort_keys=True)} if engines else None
        fig.savefig(buf, format="svg", bbox_inches="tight", metadata=meta)
        plt.close(fig)
        svg = buf.getvalue()
        self.files.put(os.path.join(self.out, "plots", fname), svg)
        body = svg[svg.find("<svg"):]
        self.html.append(f'<figure>{body}<figcaption>{html_text(caption)}</figcaption></figure>')
        self.md.append(f"![{md_escape(caption)}](plots/{fname})\n\n*{md_escape(caption)}*\n")

    def write(self, title):
        css = """body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,sans-serif;max-width:1180px;margin:2em auto;
padding:0 1em;color:#222;line-height:1.45}h1{border-bottom:2px solid #4e79a7;padding-bottom:.2em}
h2{margin-top:2em;border-bottom:1px solid #ccc}table{border-collapse:collapse;margin:.8em 0;font-size:.86em}
th,td{border:1px solid #ccc;padding:.25em .55em;text-align:right}th{background:#eef3f8}
td:first-child,th:first-child{text-align:left}tbody tr:nth-child(even){background:#fafafa}
figure{margin:1em 0}figure svg{max-width:100%;height:auto}figcaption{font-size:.85em;color:#555}
.note{font-size:.85em;color:#555}.meta{font-size:.85em;background:#f6f6f6;padding:.5em .8em;border-left:3px solid #4e79a7}
nav a{margin-right:1em}.wide{overflow-x:auto;max-width:100%}
table.compact{font-size:.72em}table.compact th,table.compact td{padding:.15em .3em}"""
        page = ["<!DOCTYPE html>", "<html lang=\"en\"><head><meta charset=\"utf-8\">",
                f"<title>{html.escape(title)}</title><style>{css}</style></head><body>",
                f"<h1>{html.escape(title)}</h1>"] + self.html + ["</body></html>"]
        self.files.put(os.path.join(self.out, "index.html"), "\n".join(page) + "\n")
        self.files.put(os.path.join(self.out, "report.md"), f"# {title}\n\n" + "\n".join(self.md) + "\n")
        self.files.commit()
