"""PDFs that slamcli writes embed no Type 3 font (IEEE PDF eXpress rejects them; issue 24 item 4).

The check reads the PDF's font dictionaries directly (matplotlib writes them as plain objects): every
``/Subtype`` of a ``/Type /Font`` object must be TrueType (or Type0/CID), and a ``/FontFile2`` (an embedded
TrueType program) must be present. With matplotlib's default (``pdf.fonttype`` 3) the same figure has
``/Subtype /Type3`` fonts, which the first test shows, so the check can fail.
"""

from __future__ import annotations

import re

import matplotlib
import pytest

matplotlib.use("Agg")

from slamcli.plots import new_figure, save_figure


def _font_subtypes(pdf: bytes) -> set[str]:
    return set(re.findall(rb"/Subtype\s*/(\w+)", pdf)) & {b"Type3", b"TrueType", b"Type0", b"Type1", b"CIDFontType2"}


def _figure():
    fig, ax = new_figure(3.5, 2.6)
    ax.plot([0, 1], [0, 1], label=r"$\hat{m}_l$ estimate")
    ax.set_xlabel("x [m]")
    ax.set_ylabel(r"ATE $\epsilon$ [m]")
    ax.set_title(r"map, $\sigma_\theta = 0.05°$")
    ax.legend()
    return fig


def test_matplotlib_default_would_embed_type3(tmp_path):
    fig = _figure()
    path = tmp_path / "default.pdf"
    with matplotlib.rc_context({"pdf.fonttype": 3}):
        fig.savefig(path)
    assert b"Type3" in _font_subtypes(path.read_bytes())


@pytest.mark.slow
def test_save_figure_pdf_has_no_type3_font(tmp_path):
    path = save_figure(_figure(), tmp_path / "fig.pdf")
    pdf = path.read_bytes()
    kinds = _font_subtypes(pdf)
    assert b"Type3" not in kinds
    assert b"TrueType" in kinds or b"CIDFontType2" in kinds
    assert b"/FontFile2" in pdf
