"""report.html's stylesheet: the screen's, and the print's (``@media print``), which
lays the page on A4 so that a certificate page fits a sheet: page 1 holds the
verdict and the as found / as left table, no figure or table is wider than the
sheet (tests/station/report/test_report_browser.py prints it with Chromium and reads the PDF)."""

from __future__ import annotations

SCREEN = """
body{font-family:-apple-system,"Segoe UI",Roboto,"Helvetica Neue",Arial,sans-serif;
 color:#1d2330;max-width:60rem;margin:2rem auto;padding:0 1.2rem;line-height:1.5;font-size:15px}
h1{font-size:1.6rem;margin:0 0 .3rem}
h2{font-size:1.2rem;margin:2rem 0 .6rem;border-bottom:1px solid #d0d5dd;padding-bottom:.2rem}
h3{font-size:1rem;margin:1.2rem 0 .4rem}
.meta{color:#555;margin:0 0 1rem}
.status{display:inline-block;padding:.15rem .7rem;border-radius:1rem;font-weight:600;
 font-size:.95rem;vertical-align:middle;margin-left:.6rem;border:1px solid}
.st-ok{background:#e6f4ea;color:#1e6b30;border-color:#9fd3ab}
.st-failed,.st-aborted{background:#fdecea;color:#a52a1a;border-color:#f0a99f}
.st-refused{background:#fff4e0;color:#8a5300;border-color:#f0c97a}
.box{background:#f6f8fa;border:1px solid #d0d5dd;border-radius:6px;padding:.7rem 1rem;
 margin:.8rem 0}
.warn{background:#fff8e6;border-color:#f0c97a}
.bad{background:#fdecea;border-color:#f0a99f}
table{border-collapse:collapse;margin:.4rem 0 1rem;font-size:.9rem;max-width:100%}
th,td{border:1px solid #d0d5dd;padding:.25rem .6rem;text-align:right;vertical-align:top}
th{background:#f0f2f5;font-weight:600}
td.l,th.l{text-align:left}
td.num{font-variant-numeric:tabular-nums;white-space:nowrap}
figure{margin:1rem 0;page-break-inside:avoid;break-inside:avoid}
figure svg{width:100%;height:auto;display:block}
figcaption{font-size:.88rem;color:#444;margin-top:.3rem}
dl.kv{display:grid;grid-template-columns:max-content auto;gap:.15rem 1rem;margin:.4rem 0}
dl.kv dt{color:#555}dl.kv dd{margin:0}
.small{font-size:.85rem;color:#555}
code{font-family:ui-monospace,Menlo,Consolas,monospace;font-size:.88em;word-break:break-all}
"""

# A4 with 12 mm margins: 186 mm of line. The type is smaller than the screen's so that
# the first sheet holds the title, the verdict and the as found / as left table; wide
# tables may wrap their figures rather than run off the sheet; every section after the
# first screen starts where it fits, and a table or figure is not cut across sheets.
PRINT = """
@page{size:A4;margin:12mm}
@media print{
 body{margin:0;padding:0;max-width:none;font-size:9.5pt;line-height:1.35}
 h1{font-size:15pt}h2{font-size:12pt;margin:1.1rem 0 .4rem;page-break-after:avoid;
 break-after:avoid}h3{font-size:10.5pt;page-break-after:avoid;break-after:avoid}
 table{font-size:8.5pt;page-break-inside:avoid;break-inside:avoid}
 th,td{padding:.12rem .35rem}
 td.num{white-space:normal}
 .box{page-break-inside:avoid;break-inside:avoid;padding:.4rem .7rem}
 figure svg{max-height:240mm}
 .status{border-width:1.5px}
}
"""

CSS = SCREEN + PRINT
