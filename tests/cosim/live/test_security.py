"""Security options: required explicitly, checked before anything connects, the password
never from the command line."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from cosim.core.errors import CosimError
from cosim.live import security
from cosim.live.server import APPLICATION_URI


def parse(*argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    security.add_arguments(p, "client")
    return p.parse_args(list(argv))


@pytest.fixture(scope="module")
def cert(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    return security.make_certificate(tmp_path_factory.mktemp("certs"), "plant",
                                     APPLICATION_URI, server=True)


def test_none_only_when_asked(monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(CosimError, match="--security: required"):
        security.from_args(parse(), "client")
    sec = security.from_args(parse("--security", "None"), "client")
    assert not sec.secure and sec.describe() == "None"


def test_policy_needs_certificate_key_and_trust(cert: tuple[Path, Path]) -> None:
    c, k = map(str, cert)
    with pytest.raises(CosimError, match="--security Basic256: expected POLICY,MODE"):
        security.from_args(parse("--security", "Basic256"), "client")
    with pytest.raises(CosimError, match="--certificate: required"):
        security.from_args(parse("--security", "Basic256Sha256,SignAndEncrypt"), "client")
    with pytest.raises(CosimError, match="--trust: required"):
        security.from_args(parse("--security", "Basic256Sha256,Sign", "--certificate", c,
                                 "--private-key", k), "client")
    with pytest.raises(CosimError, match="--certificate: given with --security None"):
        security.from_args(parse("--security", "None", "--certificate", c), "client")
    sec = security.from_args(parse("--security", "Basic256Sha256,Sign", "--certificate", c,
                                   "--private-key", k, "--trust", c), "client")
    assert sec.secure and sec.mode == "Sign" and security.trusted_files(sec) == [Path(c)]


def test_password_from_environment_never_shown(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(security.PASSWORD_ENV, "s3cret")
    sec = security.from_args(parse("--security", "None", "--user", "op"), "client")
    assert sec.password == "s3cret" and "s3cret" not in repr(sec) + sec.describe()
    monkeypatch.delenv(security.PASSWORD_ENV)
    monkeypatch.setattr("sys.stdin", None)
    with pytest.raises(CosimError, match=f"no password: set \\${security.PASSWORD_ENV}"):
        security.from_args(parse("--security", "None", "--user", "op"), "client")


def test_made_certificate_is_for_the_application(cert: tuple[Path, Path]) -> None:
    from cryptography import x509

    c = x509.load_der_x509_certificate(cert[0].read_bytes())
    uris = c.extensions.get_extension_for_class(
        x509.SubjectAlternativeName).value.get_values_for_type(x509.UniformResourceIdentifier)
    assert uris == [APPLICATION_URI]
    assert cert[1].stat().st_mode & 0o077 == 0   # the key is private


def test_make_certificate_command(tmp_path: Path) -> None:
    from cosim.cli import main

    assert main(["make-certificate", "--role", "client", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "client.der").is_file() and (tmp_path / "client.pem").is_file()
    assert main(["make-certificate", "--role", "client", "--out", str(tmp_path)]) == 2
