"""Certificates for the mutual-TLS tests, made with ``cryptography`` (a test-only dependency).

:func:`write_fleet_certs` writes what ``deploy/README.md`` asks a deployment for, in the file names the
configs of ``deploy/`` use: the fleet's CA (``ca.pem``), the router's certificate for ``localhost`` and
127.0.0.1, one client certificate per name (its CN is the name: ``uav0``, ``ground``...), and a client
certificate whose CN is ``uav0`` but which a second, rogue CA signed (``rogue.pem``). Each certificate
``NAME.pem`` has its key in ``NAME-key.pem``. Valid for a day: long enough for any test.
"""

from __future__ import annotations

import datetime
import ipaddress
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

_Issuer = tuple[ec.EllipticCurvePrivateKey, x509.Certificate]


def _name(common_name: str) -> x509.Name:
    return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)])


def _builder(subject: str, issuer: x509.Name, key: ec.EllipticCurvePrivateKey) -> x509.CertificateBuilder:
    now = datetime.datetime.now(datetime.UTC)
    return (x509.CertificateBuilder().subject_name(_name(subject)).issuer_name(issuer).public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(minutes=5)).not_valid_after(now + datetime.timedelta(days=1)))


def _authority(common_name: str) -> _Issuer:
    key = ec.generate_private_key(ec.SECP256R1())
    cert = (_builder(common_name, _name(common_name), key)
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(x509.KeyUsage(digital_signature=True, key_cert_sign=True, crl_sign=True,
                                         content_commitment=False, key_encipherment=False, data_encipherment=False,
                                         key_agreement=False, encipher_only=False, decipher_only=False),
                           critical=True)
            .sign(key, hashes.SHA256()))
    return key, cert


def _leaf(issuer: _Issuer, common_name: str, server: bool) -> _Issuer:
    ca_key, ca_cert = issuer
    key = ec.generate_private_key(ec.SECP256R1())
    usage = ExtendedKeyUsageOID.SERVER_AUTH if server else ExtendedKeyUsageOID.CLIENT_AUTH
    builder = (_builder(common_name, ca_cert.subject, key)
               .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
               .add_extension(x509.ExtendedKeyUsage([usage]), critical=False))
    if server:
        builder = builder.add_extension(x509.SubjectAlternativeName(
            [x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]), critical=False)
    return key, builder.sign(ca_key, hashes.SHA256())


def _write(folder: Path, name: str, pair: _Issuer) -> None:
    key, cert = pair
    (folder / f"{name}.pem").write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    (folder / f"{name}-key.pem").write_bytes(key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()))


def write_fleet_certs(folder: Path, clients: list[str]) -> None:
    """``ca.pem``, ``router.pem``, ``<client>.pem`` for each client and ``rogue.pem`` (CN uav0, another CA)."""
    folder.mkdir(parents=True, exist_ok=True)
    fleet_ca = _authority("skymesh test fleet CA")
    (folder / "ca.pem").write_bytes(fleet_ca[1].public_bytes(serialization.Encoding.PEM))
    _write(folder, "router", _leaf(fleet_ca, "router", server=True))
    for name in clients:
        _write(folder, name, _leaf(fleet_ca, name, server=False))
    _write(folder, "rogue", _leaf(_authority("rogue CA"), "uav0", server=False))
