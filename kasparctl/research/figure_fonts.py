"""The PDFs' TrueType fonts subset once a report, not once a file and font.

matplotlib's PDF backend hands fontTools the whole font file (DejaVu Sans, 750 kB of
glyphs and layout tables) for every font of every PDF it writes, and its text shaping
puts ligatures (fi, fl) in a second subset of the same font: two or three subsets a
file, about 0.3 s each, 18 of them and 8 of the 93 profiled seconds of a 720-session
report. Here a font is subset to one fixed set instead: printable ASCII, the few
symbols the figures print and the Latin ligatures, plus whatever a file asks for
beyond that. Every file whose text is within that set (all of the report's, in
practice) embeds the same subset, made once and kept for the process. A file's bytes
still depend on its own text only (never on the figures drawn before it), so a figure
drawn in a worker process is byte for byte the one drawn serially.

This replaces a private matplotlib function while a vector file is written; with a
matplotlib whose function is not the one expected (older versions subset by
characters, not glyphs), nothing is replaced and each file subsets as before.
"""

from __future__ import annotations

import inspect
import io
from collections.abc import Callable, Iterable, Iterator
from contextlib import AbstractContextManager, contextmanager
from typing import Any

# What the figures print beyond ASCII (labels cut with an ellipsis, dashes, signs), and
# the Latin ligatures text shaping puts in (ff, fi, fl, ffi, ffl: "different", "profile").
# (Written as escapes: the en and em dash, minus, times, plus-minus, middle dot, degree,
# micro, less and greater or equal, then the ligatures.)
EXTRA_CHARACTERS = (
    "\u2026\u2013\u2014\u2212\u00d7\u00b1\u00b7\u00b0\u00b5\u2264\u2265"
    "\ufb00\ufb01\ufb02\ufb03\ufb04"
)

Subsetter = Callable[[Any, Any], AbstractContextManager[Any]]

# (font file, face, glyphs covered) -> the subset's bytes and its glyph index map.
_made: dict[tuple[str, int, frozenset[int]], tuple[bytes, dict[int, int]]] = {}
_base: dict[tuple[str, int], frozenset[int]] = {}


def _base_glyphs(path: str, face: int) -> frozenset[int]:
    """The glyph indices of the fixed set in this font (those it has)."""
    key = (path, face)
    if key not in _base:
        from matplotlib.ft2font import FT2Font

        font = FT2Font(path, face_index=face) if face else FT2Font(path)
        charmap = font.get_charmap()
        characters = [chr(c) for c in range(0x20, 0x7F)] + list(EXTRA_CHARACTERS)
        _base[key] = frozenset(charmap[ord(c)] for c in characters if ord(c) in charmap)
    return _base[key]


def _shared(original: Subsetter) -> Subsetter:
    """`original` (matplotlib's get_glyphs_subset) made once per font and glyph set."""
    from fontTools.ttLib import TTFont  # type: ignore[import-untyped]
    from matplotlib.backends import _backend_pdf_ps

    module: Any = _backend_pdf_ps  # its font_as_file has no annotations

    def subset(fontfile: Any, glyphs: Iterable[int]) -> AbstractContextManager[Any]:
        path, face = str(fontfile), int(getattr(fontfile, "face_index", 0))
        covered = frozenset(glyphs) | _base_glyphs(path, face)
        key = (path, face, covered)
        if key not in _made:
            with original(fontfile, set(covered)) as result:
                data = module.font_as_file(result.font).getvalue()
                _made[key] = (data, dict(result.glyph_index_map))
        data, index_map = _made[key]
        # A fresh font object each time (matplotlib closes the one it is given), saved again
        # with the subset's own date: not today's, or the same figure's bytes would change.
        font = TTFont(io.BytesIO(data), recalcTimestamp=False)
        return _backend_pdf_ps.SubsetResults(font, dict(index_map))._as_cm()

    return subset


def _replaceable(module: Any) -> bool:
    function = getattr(module, "get_glyphs_subset", None)
    if function is None or not hasattr(module, "SubsetResults"):
        return False
    return list(inspect.signature(function).parameters) == ["fontfile", "glyphs"]


@contextmanager
def shared_subsets() -> Iterator[None]:
    """While in it, the PDF backend reuses each font's subset (see the module's docstring)."""
    from matplotlib.backends import _backend_pdf_ps

    module: Any = _backend_pdf_ps
    if not _replaceable(module):
        yield
        return
    original = module.get_glyphs_subset
    module.get_glyphs_subset = _shared(original)
    try:
        yield
    finally:
        module.get_glyphs_subset = original
