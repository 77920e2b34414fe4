"""``gmwm-app [FILE] [--port N] [--address A] [--allow-websocket-origin HOST:PORT] [--no-show]
[--max-upload-mb N] [--max-candidates N] [--session-jobs N] [--data-dir DIR] [--basic-auth FILE]
[--cookie-secret S] [--num-procs N] [--prebuild N]``.

Serve the GMWM app.

Every browser tab gets its own session (a fresh state). ``FILE`` is loaded (as a path on the
server) instead of the bundled demo log. Also ``python -m gmwm_app``.

Safe by default: the server listens on this machine's loopback interface only (``localhost``).
Serving beyond it (``--address 0.0.0.0`` or a network address) needs the list of origins the
browsers will use (``--allow-websocket-origin HOST:PORT``), and a shared server can ask for a
password (``--basic-auth FILE``) or an OAuth login (``--oauth-provider``, Panel's providers).
"""

from __future__ import annotations

import argparse
import json
import os
import secrets
import socket
import stat
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from engine.errors import UsageError  # the gmwm command's: one line, what to change
from gmwm_app.limits import MAX_MESSAGE_BYTES
from gmwm_app.server_guard import is_loopback

__all__ = [
    "main",
    "build_parser",
    "is_loopback",
    "read_password_file",
    "server_options",
    "expected_host",
]

#: The address served on when ``--address`` is not given: this machine only.
DEFAULT_ADDRESS = "localhost"


#: Request headers never copied into a session's token (cookies are never copied either).
TOKEN_EXCLUDED_HEADERS = ("Cookie", "Authorization", "Proxy-Authorization")


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
        default=DEFAULT_ADDRESS,
        help="address to listen on (default localhost: this machine only; 0.0.0.0 for every "
        "interface, which needs --allow-websocket-origin)",
    )
    p.add_argument(
        "--allow-websocket-origin",
        action="append",
        default=None,
        metavar="HOST[:PORT]",
        help="origin allowed to connect, as the browsers' address bar shows it (repeatable); "
        "required when --address is not a loopback address",
    )
    p.add_argument("--no-show", action="store_true", help="do not open a browser")
    p.add_argument(
        "--max-upload-mb",
        type=float,
        default=None,
        metavar="N",
        help="refuse uploads larger than N MB (default 200), while they arrive",
    )
    p.add_argument(
        "--max-candidates",
        type=int,
        default=None,
        metavar="N",
        help="candidate models one ranking (Model selection tab) may fit (default 128; "
        "3*GM+WN+QN+RW+DR has 63, 20*GM+WN+QN+RW+DR 335)",
    )
    p.add_argument(
        "--session-jobs",
        type=int,
        default=None,
        metavar="N",
        help="computations of one session running at once in the shared worker threads "
        "(default 2; its others wait their turn)",
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
    p.add_argument(
        "--basic-auth",
        default=None,
        metavar="FILE",
        help="ask for a password on a login page: FILE holds the password (its first line; any "
        'user name) or a JSON object {"user": "password", ...}; keep it private (chmod 600)',
    )
    p.add_argument(
        "--cookie-secret",
        default=None,
        metavar="SECRET",
        help="secret that signs the login cookies (default: a random one per start, so logins "
        "end when the server restarts; also PANEL_COOKIE_SECRET)",
    )
    p.add_argument(
        "--oauth-provider",
        default=None,
        metavar="NAME",
        help="log in with an OAuth provider instead (Panel's: github, google, azure, gitlab, "
        "okta, auth0, generic ...); its key and secret via --oauth-key and the environment "
        "variable PANEL_OAUTH_SECRET",
    )
    p.add_argument("--oauth-key", default=None, metavar="KEY", help="the OAuth client id")
    p.add_argument(
        "--oauth-redirect-uri",
        default=None,
        metavar="URI",
        help="the OAuth redirect URI registered with the provider",
    )
    p.add_argument(
        "--num-procs",
        type=int,
        default=1,
        metavar="N",
        help="serve from N processes sharing the port (default 1; 0: one per core); sessions "
        "are spread over them, each session stays in one",
    )
    p.add_argument(
        "--prebuild",
        type=int,
        default=None,
        metavar="N",
        help="pages each server process keeps built ahead, so that a class opening the app at "
        "once gets them at once (default 32, fewer if memory is short: about 5 MB each; 0: "
        "none); a link with a query (?source=...) builds its page on demand",
    )
    return p


def expected_host(args: argparse.Namespace, address: str) -> str | None:
    """The ``HOST:PORT`` the browsers will ask for (the first ``--allow-websocket-origin``,
    else the address served), for the pages built ahead; None when the port is not known
    yet (``--port 0``)."""
    origins = [o.strip() for o in (args.allow_websocket_origin or []) if o.strip()]
    if origins and origins[0] != "*":
        host = origins[0].split("://", 1)[-1].rstrip("/")
        return host if ":" in host.rsplit("]", 1)[-1] or not args.port else f"{host}:{args.port}"
    if not args.port:
        return None
    host = address.strip() or "localhost"
    if ":" in host and not host.startswith("["):
        host = f"[{host}]"  # an IPv6 address
    return f"{host}:{args.port}"


def read_password_file(path: str | os.PathLike[str]) -> str | dict[str, str]:
    """The password(s) of ``--basic-auth FILE``: its first line, or a JSON object mapping
    user names to passwords.

    Parameters
    ----------
    path : str or path-like
        The password file.

    Returns
    -------
    str or dict
        One password (any user name logs in with it), or ``{user: password}``.

    Raises
    ------
    UsageError
        The file is missing, not a regular file, empty or a JSON value other than an object of
        strings; the message names the file and what to write in it.
    """
    p = Path(path).expanduser()
    hint = (
        "write the password on its first line (printf '%s\\n' 'a long passphrase' > FILE; "
        "chmod 600 FILE)"
    )
    try:
        st = p.stat()
    except OSError:
        raise UsageError(f"--basic-auth: no such file: {path}: {hint}") from None
    if not stat.S_ISREG(st.st_mode):
        raise UsageError(f"--basic-auth: {path} is not a regular file: {hint}")
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        why = getattr(e, "strerror", None) or "not UTF-8 text"
        raise UsageError(f"--basic-auth: cannot read {path} ({why}): {hint}") from None
    if text.lstrip().startswith("{"):
        try:
            users = json.loads(text)
        except ValueError:
            users = None
        if (
            not isinstance(users, dict)
            or not users
            or not all(isinstance(k, str) and isinstance(v, str) and v for k, v in users.items())
        ):
            raise UsageError(
                f'--basic-auth: {path} is not a JSON object {{"user": "password", ...}} with '
                "non-empty passwords: fix it, or " + hint
            )
        return users
    lines = text.splitlines()
    password = lines[0].strip() if lines else ""
    if not password:
        raise UsageError(f"--basic-auth: the first line of {path} is empty: {hint}")
    return password


def server_options(args: argparse.Namespace) -> dict[str, Any]:
    """The keyword arguments of ``pn.serve`` for parsed ``gmwm-app`` arguments (no file read
    but ``--basic-auth``'s).

    Parameters
    ----------
    args : argparse.Namespace
        From :func:`build_parser`.

    Returns
    -------
    dict
        ``address``, ``websocket_origin`` (when given), ``websocket_max_message_size``,
        ``num_procs`` and the login options (``basic_auth`` or ``oauth_*``, ``cookie_secret``).

    Raises
    ------
    UsageError
        Serving beyond loopback without ``--allow-websocket-origin``, an empty origin, two
        login methods, a bad password file or a negative ``--num-procs``.
    """
    address = str(args.address).strip()
    origins = [o.strip() for o in (args.allow_websocket_origin or [])]
    if any(not o for o in origins):
        raise UsageError("--allow-websocket-origin: an origin is empty: give HOST or HOST:PORT")
    if not is_loopback(address) and not origins:
        shown = address or "every interface"
        port = args.port or "PORT"
        raise UsageError(
            f"--address {shown} serves beyond this machine: add --allow-websocket-origin "
            f"HOST:{port} with the host name or address the browsers will use "
            f"(e.g. --allow-websocket-origin {socket.gethostname()}:{port})"
        )
    if args.prebuild is not None and args.prebuild < 0:
        raise UsageError(f"--prebuild must be 0 (none) or more, got {args.prebuild}")
    if args.num_procs < 0:
        raise UsageError(f"--num-procs must be 0 (one per core) or more, got {args.num_procs}")
    if args.basic_auth and args.oauth_provider:
        raise UsageError("--basic-auth and --oauth-provider are two logins: give one of them")
    opts: dict[str, Any] = {
        "address": address,
        "websocket_max_message_size": MAX_MESSAGE_BYTES,
        # the session token is embedded in the page, readable by its scripts: it carries no
        # cookie (the HttpOnly login cookie stays HttpOnly) and no credential header
        "include_cookies": [],
        "exclude_headers": list(TOKEN_EXCLUDED_HEADERS),
    }
    if origins:
        opts["websocket_origin"] = origins
    if args.num_procs != 1:
        opts["num_procs"] = args.num_procs
    if args.basic_auth:
        opts["basic_auth"] = read_password_file(args.basic_auth)
    if args.oauth_provider:
        opts["oauth_provider"] = args.oauth_provider
        if args.oauth_key:
            opts["oauth_key"] = args.oauth_key
        if args.oauth_redirect_uri:
            opts["oauth_redirect_uri"] = args.oauth_redirect_uri
    if args.basic_auth or args.oauth_provider:
        # the login cookie is signed; every process of --num-procs must share the secret
        opts["cookie_secret"] = args.cookie_secret or secrets.token_urlsafe(32)
    elif args.cookie_secret:
        opts["cookie_secret"] = args.cookie_secret
    return opts


def _notes(args: argparse.Namespace, opts: dict[str, Any]) -> list[str]:
    """One-line notes printed at start about what the options imply."""
    out = []
    if "*" in opts.get("websocket_origin", ()):
        out.append("gmwm-app: --allow-websocket-origin '*': pages served from any site may connect")
    if not is_loopback(opts["address"]) and not ("basic_auth" in opts or "oauth_provider" in opts):
        out.append(
            "gmwm-app: no login: anyone who reaches this address can use the app "
            "(add --basic-auth FILE for a password)"
        )
    if args.num_procs != 1 and not args.no_show:
        out.append("gmwm-app: --num-procs: not opening a browser (each process would)")
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """Run the server until interrupted (Ctrl+C); returns the exit status."""
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
    try:
        opts = server_options(args)
    except UsageError as e:
        print(f"gmwm-app: error: {e}", file=sys.stderr)
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
    for flag, value in (
        ("--max-candidates", args.max_candidates),
        ("--session-jobs", args.session_jobs),
    ):
        if value is not None and value < 1:
            print(f"gmwm-app: error: {flag} must be at least 1, got {value}", file=sys.stderr)
            return 2
    limits.configure(
        max_upload_mb=args.max_upload_mb,
        data_dirs=dirs,
        allowed_files=[path] if path else (),
        max_candidates=args.max_candidates,
        session_jobs=args.session_jobs,
    )
    for note in _notes(args, opts):
        print(note, file=sys.stderr)

    import panel as pn

    from gmwm_app import server_guard
    from gmwm_app.server import create_application, default_prebuild

    server_guard.install(opts.get("websocket_origin", ()), args.port, login="basic_auth" in opts)

    def pool_full(n: int) -> None:
        print(f"gmwm-app: {n} pages ready ahead (process {os.getpid()})", file=sys.stderr)

    application = create_application(
        path,
        prebuild=default_prebuild() if args.prebuild is None else args.prebuild,
        host=expected_host(args, opts["address"]),
        on_full=pool_full,
    )
    try:
        pn.serve(
            {"/": application},
            port=args.port,
            show=not args.no_show and args.num_procs == 1,
            title="GMWM",
            **opts,
        )
    except KeyboardInterrupt:  # Ctrl+C outside Panel's handler (--num-procs' parent process)
        pass
    from tornado.process import task_id

    if task_id() is None:  # once, not from every process of --num-procs
        print("gmwm-app: stopped", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
