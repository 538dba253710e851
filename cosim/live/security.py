"""The security of an OPC UA connection: policy and mode, certificate, trust list, user.

Plants ask for signed and encrypted connections (``Basic256Sha256,SignAndEncrypt``) between
applications that each hold a certificate, with the peer's certificate in a trust list, and
for a user. Both ``cosim serve-plant`` and ``cosim run --plant opc.tcp://...`` take the same
options (:func:`add_arguments`); no security at all only when asked (``--security None``),
and the command then says so.

The password is never an argument: it comes from the environment variable
:data:`PASSWORD_ENV`, else from a prompt on a terminal; it is kept out of logs and results.
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cosim.core.errors import CosimError

__all__ = ["MODES", "PASSWORD_ENV", "POLICIES", "Security", "add_arguments", "from_args",
           "make_certificate"]

#: The environment variable holding the user's password.
PASSWORD_ENV = "COSIM_OPCUA_PASSWORD"
#: Security policies offered (asyncua's names).
POLICIES = ("Basic256Sha256", "Aes128Sha256RsaOaep", "Aes256Sha256RsaPss")
#: Message security modes.
MODES = ("Sign", "SignAndEncrypt")


@dataclass(frozen=True)
class Security:
    """How a connection is secured.

    Attributes
    ----------
    policy : str or None
        ``"Basic256Sha256"`` … (:data:`POLICIES`); ``None``: no security.
    mode : str
        ``"Sign"`` or ``"SignAndEncrypt"`` (ignored without a policy).
    certificate, private_key : Path or None
        This application's certificate (DER or PEM) and its private key (PEM).
    trust : tuple of Path
        Certificates (files, or folders of them) of the peers this application trusts: the
        server's, for a client; the clients', for a server.
    user : str or None
        The user name (a client logs in with it; a server accepts only it).
    password : str or None
        The user's password (:data:`PASSWORD_ENV` or a prompt); never printed (``repr``
        hides it).
    """

    policy: str | None = None
    mode: str = "SignAndEncrypt"
    certificate: Path | None = None
    private_key: Path | None = None
    trust: tuple[Path, ...] = ()
    user: str | None = None
    password: str | None = field(default=None, repr=False)

    @property
    def secure(self) -> bool:
        """Whether messages are signed (and encrypted)."""
        return self.policy is not None

    def describe(self) -> str:
        """``"Basic256Sha256,SignAndEncrypt, user 'op'"``, or ``"None"``; for summaries."""
        text = f"{self.policy},{self.mode}" if self.secure else "None"
        return text + (f", user {self.user!r}" if self.user else "")


def add_arguments(parser: argparse.ArgumentParser, role: str) -> None:
    """``--security``, ``--certificate``, ``--private-key``, ``--trust`` and ``--user``.

    ``role`` is ``"client"`` or ``"server"`` (it words the help).
    """
    peer = "server's" if role == "client" else "clients'"
    g = parser.add_argument_group("security (OPC UA)")
    g.add_argument("--security", metavar="POLICY,MODE", default=None,
                   help=f"{'|'.join(POLICIES)} with {' or '.join(MODES)} (e.g. "
                        "Basic256Sha256,SignAndEncrypt), or None for no security at all "
                        "(then said so); required" + (" for a live plant" if role == "client"
                                                      else ""))
    g.add_argument("--certificate", metavar="CERT", default=None,
                   help="this application's certificate (.der or .pem)")
    g.add_argument("--private-key", metavar="KEY", default=None,
                   help="its private key (.pem)")
    g.add_argument("--trust", metavar="PATH", action="append", default=[],
                   help=f"a certificate, or a folder of them, that the {peer} certificate "
                        "must be among (repeatable); required with a security policy")
    g.add_argument("--user", metavar="NAME", default=None,
                   help=("log in as NAME" if role == "client" else "accept only NAME") +
                        f"; the password comes from ${PASSWORD_ENV} or a prompt, never from "
                        "the command line")


def from_args(args: argparse.Namespace, role: str) -> Security:
    """The :class:`Security` the options ask for (the password read here).

    Raises
    ------
    CosimError
        No ``--security``; an unknown policy or mode; a missing certificate, key or trust
        list; a user without a password (none in the environment and no terminal).
    """
    text = args.security
    if text is None:
        raise CosimError("--security: required: a policy and mode (e.g. "
                         "Basic256Sha256,SignAndEncrypt with --certificate, --private-key "
                         "and --trust), or None to connect without any security")
    password = None
    if args.user is not None:
        password = read_password(args.user)
    if text.strip().lower() == "none":
        extra = [flag for flag, value in (("--certificate", args.certificate),
                                          ("--private-key", args.private_key),
                                          ("--trust", args.trust)) if value]
        if extra:
            raise CosimError(f"{extra[0]}: given with --security None (no security uses no "
                             "certificate)")
        return Security(user=args.user, password=password)
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != 2 or parts[0] not in POLICIES or parts[1] not in MODES:
        raise CosimError(f"--security {text}: expected POLICY,MODE with POLICY one of "
                         f"{', '.join(POLICIES)} and MODE {' or '.join(MODES)}, or None")
    paths = {}
    for flag, value in (("--certificate", args.certificate),
                        ("--private-key", args.private_key)):
        if value is None:
            raise CosimError(f"{flag}: required with --security {text}")
        path = Path(value)
        if not path.is_file():
            raise CosimError(f"{flag} {value}: file not found")
        paths[flag] = path
    if not args.trust:
        peer = "server's" if role == "client" else "clients'"
        raise CosimError(f"--trust: required with --security {text}: the {peer} certificate "
                         "must be in a trust list")
    trust = []
    for value in args.trust:
        path = Path(value)
        if not path.exists():
            raise CosimError(f"--trust {value}: not found")
        trust.append(path)
    return Security(policy=parts[0], mode=parts[1], certificate=paths["--certificate"],
                    private_key=paths["--private-key"], trust=tuple(trust), user=args.user,
                    password=password)


def read_password(user: str) -> str:
    """The password of ``user``: :data:`PASSWORD_ENV`, else a prompt on a terminal.

    Raises
    ------
    CosimError
        Neither is available.
    """
    password = os.environ.get(PASSWORD_ENV)
    if password is not None:
        return password
    if sys.stdin is not None and sys.stdin.isatty():
        import getpass

        return getpass.getpass(f"OPC UA password of {user}: ")
    raise CosimError(f"--user {user}: no password: set ${PASSWORD_ENV} (it is never taken "
                     "from the command line)")


def trusted_files(security: Security) -> list[Path]:
    """The trust list's certificate files: those named, and in each folder named its
    ``.der`` and ``.crt`` files and the ``.pem`` files that hold a certificate (not a
    key), sorted."""
    files: list[Path] = []
    for path in security.trust:
        if not path.is_dir():
            files.append(path)
            continue
        for p in sorted(path.iterdir()):
            kind = p.suffix.lower()
            if kind in (".der", ".crt") or (
                    kind == ".pem" and b"BEGIN CERTIFICATE" in p.read_bytes()[:4096]):
                files.append(p)
    return files


async def validator(security: Security, peer: str) -> Any:
    """A certificate validator that accepts a peer (``"client"`` or ``"server"``) whose
    certificate is in the trust list (or issued by a certificate there), valid now, for the
    application it says it is."""
    from asyncua.crypto import uacrypto
    from asyncua.crypto.truststore import TrustStore
    from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions
    from cryptography import x509

    files = trusted_files(security)

    class FileTrustStore(TrustStore):
        """asyncua's trust store over certificate files (its own takes folders only)."""

        async def load_trust(self) -> None:
            certs = [await uacrypto.load_certificate(f) for f in files]
            self._trust_store = x509.verification.Store(certs) if certs else None

    store = FileTrustStore([], [])
    try:
        await store.load()
    except Exception as exc:
        raise CosimError(f"--trust: cannot read the trust list ({', '.join(map(str, files))}): "
                         f"{type(exc).__name__}: {exc}") from None
    options = CertificateValidatorOptions.TRUSTED_VALIDATION | (
        CertificateValidatorOptions.PEER_CLIENT if peer == "client"
        else CertificateValidatorOptions.PEER_SERVER)
    return CertificateValidator(options, store)


async def secure_server(server: Any, security: Security, users: bool) -> None:
    """An asyncua ``server``'s endpoint policy, certificate, client validator (the trust
    list) and identity tokens (user names with ``users``, else anonymous) from ``security``:
    the virtual plant's and the faceplate's."""
    from asyncua import ua

    if security.secure:
        server.set_security_policy(
            [getattr(ua.SecurityPolicyType, f"{security.policy}_{security.mode}")])
        await server.load_certificate(str(security.certificate))
        await server.load_private_key(str(security.private_key))
        server.set_certificate_validator(await validator(security, "client"))
    else:
        server.set_security_policy([ua.SecurityPolicyType.NoSecurity])
    server.set_identity_tokens([ua.UserNameIdentityToken] if users
                               else [ua.AnonymousIdentityToken])


def make_certificate(folder: str | Path, name: str, uri: str, *, server: bool,
                     host: str = "localhost", days: int = 365) -> tuple[Path, Path]:
    """A self-signed application certificate ``folder/name.der`` and its key ``name.pem``.

    For a rehearsal and for tests; a plant's certificates come from its site's authority.
    ``uri`` is the application URI (it must match the application's: the server's
    :data:`cosim.live.server.APPLICATION_URI` or the client's
    :data:`cosim.live.session.APPLICATION_URI`).
    """
    from asyncua.crypto import cert_gen
    from cryptography import x509
    from cryptography.hazmat.primitives.serialization import Encoding
    from cryptography.x509.oid import ExtendedKeyUsageOID

    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    key = cert_gen.generate_private_key()
    use = [ExtendedKeyUsageOID.SERVER_AUTH if server else ExtendedKeyUsageOID.CLIENT_AUTH]
    cert = cert_gen.generate_self_signed_app_certificate(
        key, name, {}, [x509.UniformResourceIdentifier(uri), x509.DNSName(host)], extended=use,
        days=days)
    cert_path, key_path = out / f"{name}.der", out / f"{name}.pem"
    cert_path.write_bytes(cert.public_bytes(Encoding.DER))
    key_path.write_bytes(cert_gen.dump_private_key_as_pem(key))
    key_path.chmod(0o600)
    return cert_path, key_path
