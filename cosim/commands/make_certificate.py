"""``cosim make-certificate``: a self-signed OPC UA application certificate and its key."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cosim.core.errors import exit_codes_help

DESCRIPTION = """\
Make a self-signed OPC UA application certificate (DER) and its private key (PEM, readable by
its owner only) for cosim serve-plant (--role server) or cosim run --plant opc.tcp://...
(--role client), to rehearse a secured connection. Each side then trusts the other's
certificate (--trust). A plant's own certificates come from its site's authority.
"""

EPILOG = """\
examples:
  cosim make-certificate --role server --out pki/plant
  cosim make-certificate --role client --out pki/client
  cosim serve-plant --security Basic256Sha256,SignAndEncrypt --certificate pki/plant/plant.der \\
      --private-key pki/plant/plant.pem --trust pki/client/client.der

""" + exit_codes_help()


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``make-certificate`` sub-command."""
    p = subparsers.add_parser(
        "make-certificate", help="make a self-signed OPC UA certificate for serve-plant or a "
                                 "live run", description=DESCRIPTION, epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--role", choices=("server", "client"), required=True,
                   help="server: cosim serve-plant's; client: cosim run's")
    p.add_argument("--out", metavar="DIR", default=".",
                   help="folder for NAME.der and NAME.pem (default: here)")
    p.add_argument("--name", metavar="NAME", default=None,
                   help="file and common name (default: plant for a server, client for a "
                        "client)")
    p.add_argument("--host", metavar="HOST", default="localhost",
                   help="the host name the certificate is for (default localhost)")
    p.add_argument("--days", metavar="N", type=int, default=365,
                   help="validity in days (default 365)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``cosim make-certificate``; returns the exit code."""
    from cosim.core.errors import CosimError
    from cosim.live.security import make_certificate
    from cosim.live.server import APPLICATION_URI as SERVER_URI
    from cosim.live.session import APPLICATION_URI as CLIENT_URI

    if args.days < 1:
        raise CosimError(f"--days {args.days}: must be at least 1")
    server = args.role == "server"
    name = args.name or ("plant" if server else "client")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise CosimError(f"--out {out}: not a folder")
    for suffix in (".der", ".pem"):
        if (out / f"{name}{suffix}").exists():
            raise CosimError(f"{out / (name + suffix)}: exists; remove it or choose --name")
    cert, key = make_certificate(out, name, SERVER_URI if server else CLIENT_URI,
                                 server=server, host=args.host, days=args.days)
    print(f"cosim make-certificate: {cert} (certificate, {args.role}), {key} (private key)",
          file=sys.stderr)
    return 0
