"""Reading a YAML mapping with PyYAML (``yaml.safe_load``), OpenCV's ``%YAML:1.0`` files too.

Every YAML file the engine reads (a Kalibr ``imu.yaml``, a filter's settings file for ``gmwm
check``) goes through :func:`read_yaml_mapping`: the full YAML syntax (flow maps and lists,
comments, anchors and aliases, quoted keys, block scalars), plus what OpenCV's ``FileStorage``
writes (VINS-Fusion and ORB-SLAM3 settings): the ``%YAML:1.0`` first line, which is not a YAML
directive, and ``!!opencv-matrix`` entries, read as their ``data``. Numbers in scientific
notation without a dot or without an exponent sign (``1e-05``, ``1.6e4``: floats in YAML 1.2
and in OpenCV, strings to PyYAML's YAML 1.1) are read as floats.
"""

from __future__ import annotations

import re
from typing import Any

import yaml

__all__ = ["read_yaml_mapping", "OPENCV_HEADER"]

#: OpenCV's first line (``cv::FileStorage``): a YAML processor rejects it as a directive.
OPENCV_HEADER = re.compile(r"\A\ufeff?%YAML:\d+\.\d+[ \t]*(?:\r?\n|\Z)")

_FLOAT_12 = re.compile(
    r"""^(?:[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+
        |[-+]?\.[0-9_]+[eE][-+]?[0-9]+)$""",
    re.X,
)


class _Loader(yaml.SafeLoader):
    """``yaml.SafeLoader`` plus YAML 1.2 floats and OpenCV matrices (this module's docstring)."""


def _opencv_matrix(loader: yaml.SafeLoader, node: yaml.Node) -> list[Any]:
    """An ``!!opencv-matrix`` (``rows``, ``cols``, ``dt``, ``data``) as its data: a flat list
    for a vector, a list of rows otherwise."""
    if not isinstance(node, yaml.MappingNode):
        raise yaml.constructor.ConstructorError(
            None, None, "an !!opencv-matrix is a mapping (rows, cols, dt, data)", node.start_mark
        )
    m = loader.construct_mapping(node, deep=True)
    data, rows, cols = m.get("data"), m.get("rows"), m.get("cols")
    if not isinstance(data, list) or not isinstance(rows, int) or not isinstance(cols, int):
        raise yaml.constructor.ConstructorError(
            None,
            None,
            "an !!opencv-matrix needs integer rows and cols and a data list",
            node.start_mark,
        )
    if rows * cols != len(data):
        raise yaml.constructor.ConstructorError(
            None,
            None,
            f"an !!opencv-matrix of {rows}x{cols} has {len(data)} data values",
            node.start_mark,
        )
    if rows == 1 or cols == 1:
        return data
    return [data[i * cols : (i + 1) * cols] for i in range(rows)]


_Loader.add_implicit_resolver("tag:yaml.org,2002:float", _FLOAT_12, list("-+0123456789."))
_Loader.add_constructor("tag:yaml.org,2002:opencv-matrix", _opencv_matrix)


def read_yaml_mapping(
    text: str, where: str, *, error: type[Exception] = ValueError
) -> dict[Any, Any]:
    """The mapping a YAML document holds (module docstring for the syntax read).

    Parameters
    ----------
    text : str
        The document (an OpenCV ``%YAML:1.0`` first line is dropped).
    where : str
        How messages name the document (a file name).
    error : exception class
        Raised, with a one-line message, for text that is not YAML or whose document is not a
        mapping of ``key: value`` (an empty document is an empty mapping).

    Returns
    -------
    dict
    """
    body = OPENCV_HEADER.sub("", text, count=1)
    dropped = 1 if body != text else 0  # the header's line, for the line numbers
    try:
        doc = yaml.load(body, Loader=_Loader)  # a SafeLoader: no Python object is built
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None) or getattr(e, "context_mark", None)
        at = f" at line {mark.line + 1 + dropped}" if mark is not None else ""
        what = getattr(e, "problem", None) or str(e).splitlines()[0]
        raise error(f"{where} is not YAML{at}: {what}; fix the file or give a YAML file") from None
    except RecursionError:
        raise error(f"{where} is not YAML this reader accepts: nested too deeply") from None
    if doc is None:
        return {}
    if not isinstance(doc, dict):
        found = "a list" if isinstance(doc, list) else f"one {type(doc).__name__} value"
        raise error(
            f"{where}: not 'key: value' YAML (the document is {found}); "
            "fix the file or give a YAML file of 'key: value' lines"
        )
    return doc
