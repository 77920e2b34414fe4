"""``gmwm-app [FILE] [--port N] [--address A] [--no-show] [--max-upload-mb N] [--data-dir DIR]``.

Serve the GMWM app.

Every browser tab gets its own session (a fresh state). ``FILE`` is loaded (as a path on the
server) instead of the bundled demo log. Also ``python -m gmwm_app``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

__all__ = ["main", "build_parser"]

_LOCAL = {"localhost", "127.0.0.1", "::1"}


def build_parser() -> argparse.ArgumentParser:
    """The command-line parser of ``gmwm-app``."""
    p = argparse.ArgumentParser(
        prog="gmwm-app",
        description="Serve the GMWM browser app: load an IMU log, build a latent model "
        "live, read its parameters.",
    )
    p.add_argument(
        "file",
        nargs="?",
        metavar="FILE",
        help="log to open (CSV/TSV/text, NPY/NPZ, HDF5, WV summary HDF5); "
        "default: the bundled demo log",
    )
    p.add_argument(
        "--port", type=int, default=5006, help="port to serve on (default 5006; 0 picks a free one)"
    )
    p.add_argument(
        "--address",
        default=None,
        help="address to listen on (default localhost; 0.0.0.0 for every interface)",
    )
    p.add_argument(
        "--allow-websocket-origin",
        action="append",
        default=None,
        metavar="HOST[:PORT]",
        help="extra origin allowed to connect (needed when serving beyond localhost)",
    )
    p.add_argument("--no-show", action="store_true", help="do not open a browser")
    p.add_argument(
        "--max-upload-mb",
        type=float,
        default=None,
        metavar="N",
        help="refuse uploads larger than N MB (default 200)",
    )
    p.add_argument(
        "--data-dir",
        action="append",
        default=None,
        metavar="DIR",
        help="folder whose files may be loaded by server path (repeatable; default: "
        "the current directory, the bundled demo's folder and, in a checkout, the "
        "shared data folder next to the repository); other paths are refused",
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run the server until interrupted; returns the exit status."""
    args = build_parser().parse_args(argv)
    path = None
    if args.file:
        f = Path(args.file).expanduser()
        if not (f.is_file() or (f / "metadata.yaml").is_file()):  # a log, or a ROS 2 bag folder
            print(f"gmwm-app: error: no such file (or ROS 2 bag folder): {f}", file=sys.stderr)
            return 2
        path = str(f.resolve())
    if not 0 <= args.port <= 65535:
        print(f"gmwm-app: error: --port must be 0..65535, got {args.port}", file=sys.stderr)
        return 2

    from gmwm_app import limits

    dirs = args.data_dir if args.data_dir else limits.default_data_dirs()
    missing = [d for d in dirs if not Path(d).expanduser().is_dir()]
    if missing:
        print(f"gmwm-app: error: --data-dir is not a folder: {missing[0]}", file=sys.stderr)
        return 2
    if args.max_upload_mb is not None and not args.max_upload_mb > 0:
        print(
            f"gmwm-app: error: --max-upload-mb must be positive, got {args.max_upload_mb}",
            file=sys.stderr,
        )
        return 2
    limits.configure(
        max_upload_mb=args.max_upload_mb, data_dirs=dirs, allowed_files=[path] if path else ()
    )

    import panel as pn

    from gmwm_app.server import create_application

    kwargs = {}
    origins = list(args.allow_websocket_origin or [])
    if args.address and args.address not in _LOCAL and not origins:
        origins = ["*"]
        print(
            "gmwm-app: serving beyond localhost: any origin may connect; "
            "restrict it with --allow-websocket-origin",
            file=sys.stderr,
        )
    if origins:
        kwargs["websocket_origin"] = origins
    pn.serve(
        {"/": create_application(path)},
        port=args.port,
        address=args.address,
        show=not args.no_show,
        title="GMWM",
        websocket_max_message_size=64 * 1024 * 1024,
        **kwargs,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
