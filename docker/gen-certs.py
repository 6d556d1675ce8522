#!/usr/bin/env python3
"""Generate X.509 v3 test certificates for Zenoh mutual TLS: one CA, one certificate per name.

rustls (Zenoh's TLS) refuses X.509 v1 certificates and wants PKCS#8 keys, which
is what ``openssl req -x509`` without extensions does not give; this script
makes v3 certificates (basic constraints, key usage, subject alternative names)
with ECDSA P-256 keys in PKCS#8 PEM.  The common name is the ACL subject
(``cert_common_names`` in ``zenoh-router-mtls.json5``), so name every
principal exactly as ``pfp acl --tls`` does: ``router``, ``planner``,
``unit-<id>``, ...

    python docker/gen-certs.py --out docker/certs router planner fleet unit-m1
    python docker/gen-certs.py --out docker/certs --names-file docker/certs/names.txt

Writes ``ca.pem`` (and ``ca-key.pem``, kept to sign more names later) and, per
name, ``<name>.pem`` and ``<name>-key.pem``.  An existing CA in ``--out`` is
reused, so adding a unit does not invalidate the others.  Test certificates
only: the CA key sits next to them.  Needs the ``cryptography`` package
(``pip install 'pfp-service[certs]'``).
"""

from __future__ import annotations

import argparse
import datetime
import ipaddress
import os
import re
import sys
from pathlib import Path

NAME = re.compile(r"^[A-Za-z0-9_-]{1,64}$")
# Every certificate also answers to these, so "tls/localhost:7447" and
# "tls/127.0.0.1:7447" verify on a test machine.
LOCAL_DNS = ("localhost",)
LOCAL_IPS = ("127.0.0.1", "::1")


def _key():  # type: ignore[no-untyped-def]
    from cryptography.hazmat.primitives.asymmetric import ec

    return ec.generate_private_key(ec.SECP256R1())


def _pem_key(key) -> bytes:  # type: ignore[no-untyped-def]
    from cryptography.hazmat.primitives import serialization

    return key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
    )


def _write(path: Path, data: bytes, private: bool = False) -> None:
    path.write_bytes(data)
    if private:
        os.chmod(path, 0o600)


def _load_or_make_ca(out: Path, days: int):  # type: ignore[no-untyped-def]
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.x509.oid import NameOID

    cert_path, key_path = out / "ca.pem", out / "ca-key.pem"
    if cert_path.exists() and key_path.exists():
        cert = x509.load_pem_x509_certificate(cert_path.read_bytes())
        key = serialization.load_pem_private_key(key_path.read_bytes(), password=None)
        return cert, key
    key = _key()
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "pfp-test-ca")])
    now = datetime.datetime.now(datetime.UTC)
    cert = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                key_cert_sign=True,
                crl_sign=True,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .sign(key, hashes.SHA256())
    )
    _write(cert_path, cert.public_bytes(serialization.Encoding.PEM))
    _write(key_path, _pem_key(key), private=True)
    return cert, key


def issue(out: Path, name: str, ca_cert, ca_key, days: int) -> None:  # type: ignore[no-untyped-def]
    """Write ``<name>.pem`` and ``<name>-key.pem``: a v3 leaf for TLS server and client use."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    key = _key()
    now = datetime.datetime.now(datetime.UTC)
    alt: list[x509.GeneralName] = [x509.DNSName(name), *(x509.DNSName(d) for d in LOCAL_DNS)]
    alt += [x509.IPAddress(ipaddress.ip_address(ip)) for ip in LOCAL_IPS]
    cert = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)]))
        .issuer_name(ca_cert.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                key_cert_sign=False,
                crl_sign=False,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(
            x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]),
            critical=False,
        )
        .add_extension(x509.SubjectAlternativeName(alt), critical=False)
        .add_extension(
            x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False
        )
        .sign(ca_key, hashes.SHA256())
    )
    _write(out / f"{name}.pem", cert.public_bytes(serialization.Encoding.PEM))
    _write(out / f"{name}-key.pem", _pem_key(key), private=True)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="gen-certs.py", description=__doc__.splitlines()[0])
    p.add_argument("names", nargs="*", metavar="NAME", help="common names, e.g. router planner unit-m1")
    p.add_argument("--out", required=True, metavar="DIR", help="where to write the PEM files")
    p.add_argument("--names-file", metavar="FILE", help="more names, one a line ('pfp acl --tls' writes one)")
    p.add_argument("--days", type=int, default=30, help="validity in days (default 30)")
    args = p.parse_args(argv)
    names = list(args.names)
    if args.names_file:
        try:
            names += [ln.strip() for ln in Path(args.names_file).read_text().splitlines() if ln.strip()]
        except OSError as exc:
            print(f"gen-certs.py: {args.names_file}: cannot read: {exc.strerror or exc}", file=sys.stderr)
            return 2
    bad = [n for n in names if not NAME.match(n)]
    if bad or not names:
        print(f"gen-certs.py: names must be 1-64 of [A-Za-z0-9_-], got {bad or 'none'}", file=sys.stderr)
        return 2
    if not 1 <= args.days <= 3650:
        print("gen-certs.py: --days: must be 1 to 3650", file=sys.stderr)
        return 2
    try:
        import cryptography  # noqa: F401
    except ImportError:
        print("gen-certs.py: needs the 'cryptography' package (pip install cryptography)", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    ca_cert, ca_key = _load_or_make_ca(out, args.days)
    for name in dict.fromkeys(names):
        issue(out, name, ca_cert, ca_key, args.days)
    print(f"gen-certs.py: CA and {len(set(names))} certificates in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
