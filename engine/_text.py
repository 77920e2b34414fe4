"""User-given text (file and channel names, units) made safe for a spreadsheet.

A CSV cell that starts with ``=``, ``+``, ``-`` or ``@`` is a formula to Excel, LibreOffice and
Google Sheets: a channel named ``=cmd|' /C calc'!A0`` in a CSV header runs a command when the
file is opened (CSV injection, OWASP). Every CSV the engine writes passes its text cells through
:func:`spreadsheet_safe` (the export formats through ``engine.formats.common.csv_cells``, the
fleet summary, ``save_log``'s header), which makes such a cell text with a leading ``'``.
Numbers written as text (``-1.5e-3``) are left alone.
"""

from __future__ import annotations

__all__ = ["spreadsheet_safe"]

#: First characters that make a cell a formula (with their full-width forms, which some
#: spreadsheets fold to ASCII).
FORMULA_START = frozenset("=+-@\uff1d\uff0b\uff0d\uff20")


def spreadsheet_safe(text: str) -> str:
    """``text`` as a CSV cell no spreadsheet evaluates: ``"'" + text`` when it starts with a
    formula character (:data:`FORMULA_START`) and is not a number, else unchanged.

    >>> spreadsheet_safe("=cmd|' /C calc'!A0")
    "'=cmd|' /C calc'!A0"
    >>> spreadsheet_safe("-1.5e-3"), spreadsheet_safe("gyro_x")
    ('-1.5e-3', 'gyro_x')
    """
    if not text or text[0] not in FORMULA_START:
        return text
    try:
        float(text)
    except ValueError:
        return "'" + text
    return text
