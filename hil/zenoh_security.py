"""``--secure``: mutual TLS between hil's processes and an access policy by role.

``hil keys init DIR`` makes a certificate authority and one certificate per role
(:data:`ROLES`), each named by its role in its Common Name. A process started with
``--secure DIR`` speaks TLS only (``tcp/`` endpoints become ``tls/``), shows its role's
certificate and accepts only peers whose certificate the same CA signed (mutual TLS: a
client of another CA cannot connect).

Every process enforces the policy on what it receives (Zenoh's access control, ingress,
subjects by certificate Common Name), so a frame is refused by the process that would act
on it: the drives' own process refuses a CAN frame from an operator or an observer, the
controller refuses an observer's goal or fault reset. Peers link directly (no relay,
``hil.zenoh_session``), so the certificate a process checks is the sender's own. A
certificate of the CA with any other name matches no policy and is refused everything
(default deny).

- ``drives`` (``hil sim``) and ``controller`` (``hil control``): everything;
- ``operator`` (``hil send``, ``hil reset``): everything but CAN frames;
- ``observer`` (``hil viz``): subscribes and reads only: no frame, no goal, no cancel, no
  reset, nothing published.

The certificates carry no host names, and names are not verified on connect: a peer is
whoever holds a key the CA signed, wherever it connects from.
"""

from __future__ import annotations

import datetime
import json
from dataclasses import dataclass
from pathlib import Path

from hil.errors import HilError

#: the roles and the commands that take each
ROLES = {"drives": "hil sim", "controller": "hil control", "operator": "hil send, hil reset",
         "observer": "hil viz"}
CA_CERTIFICATE = "ca.pem"
CA_KEY = "ca.key"
#: how long the certificates of ``hil keys init`` are valid (days)
VALID_DAYS = 3650

#: keys whose puts command the drives
FRAME_KEYS = ["hil/can/**"]
#: queries that command the controller (an action's goals and cancels, wherever its
#: namespace puts it, and the fault reset; tests/test_secure.py holds them against the keys
#: the controller serves)
COMMAND_KEYS = ["hil/*/**/send_goal", "hil/*/**/cancel_goal", "hil/*/reset_faults"]
EVERY_MESSAGE = ["put", "delete", "declare_subscriber", "query", "reply", "declare_queryable",
                 "liveliness_token", "liveliness_query", "declare_liveliness_subscriber"]


@dataclass(frozen=True)
class Identity:
    """A process' role and the files of its certificate, key and CA."""

    role: str
    ca: Path
    certificate: Path
    key: Path

    @classmethod
    def of(cls, folder: Path, role: str) -> Identity:
        """The identity of ``role`` in a folder made by :func:`make_keys` (HilError naming
        what is missing)."""
        folder = Path(folder)
        identity = cls(role, folder / CA_CERTIFICATE, folder / f"{role}.pem",
                       folder / f"{role}.key")
        missing = [p for p in (identity.ca, identity.certificate, identity.key)
                   if not p.is_file()]
        if missing:
            raise HilError.single(f"--secure {folder}: no {', '.join(p.name for p in missing)}",
                                  hint=f"make the keys with `hil keys init {folder}`")
        return identity

    def zenoh_json(self) -> dict[str, str]:
        """Zenoh config entries (key path -> JSON5 value): mutual TLS and the policy."""
        tls = {"root_ca_certificate": str(self.ca), "enable_mtls": True,
               "listen_certificate": str(self.certificate), "listen_private_key": str(self.key),
               "connect_certificate": str(self.certificate),
               "connect_private_key": str(self.key), "verify_name_on_connect": False}
        entries = {f"transport/link/tls/{name}": json.dumps(value) for name, value in tls.items()}
        entries["access_control"] = json.dumps(access_policy())
        return entries


def access_policy() -> dict:
    """Zenoh's access_control section: the roles' rights (module doc), enforced on what a
    process receives."""
    def rule(rule_id, permission, messages, keys, flows=("ingress",)):
        return {"id": rule_id, "permission": permission, "messages": messages,
                "key_exprs": keys, "flows": list(flows)}

    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": [
            rule("anything", "allow", EVERY_MESSAGE, ["**"], ("ingress", "egress")),
            rule("no frames", "deny", ["put", "delete"], FRAME_KEYS),
            rule("no commands", "deny", ["query"], COMMAND_KEYS),
            rule("no publishing", "deny", ["put", "delete"], ["hil/**"]),
        ],
        "subjects": [{"id": role, "cert_common_names": [role]} for role in ROLES],
        "policies": [
            {"rules": ["anything"], "subjects": list(ROLES)},
            {"rules": ["no frames"], "subjects": ["operator"]},
            {"rules": ["no frames", "no commands", "no publishing"], "subjects": ["observer"]},
        ],
    }


def secured_endpoint(endpoint: str) -> str:
    """``endpoint`` over TLS: ``tcp/`` becomes ``tls/``; anything else but ``tls/`` is
    refused."""
    if endpoint.startswith("tls/"):
        return endpoint
    if endpoint.startswith("tcp/"):
        return "tls/" + endpoint[len("tcp/"):]
    raise HilError.single(f"--secure: endpoint {endpoint} is not TCP or TLS",
                          hint="give tcp/HOST:PORT or tls/HOST:PORT endpoints")


def make_keys(folder: Path) -> list[Path]:
    """A CA and a certificate and key per role in ``folder`` (made if missing); the files
    written. Refuses to overwrite an existing CA."""
    # lazily: only `hil keys` needs it
    from cryptography import x509                                     # noqa: PLC0415
    from cryptography.hazmat.primitives import hashes, serialization   # noqa: PLC0415
    from cryptography.hazmat.primitives.asymmetric import ec           # noqa: PLC0415
    from cryptography.x509.oid import NameOID                          # noqa: PLC0415

    folder = Path(folder)
    if (folder / CA_KEY).exists():
        raise HilError.single(f"{folder / CA_KEY} exists: keys were made there already",
                              hint="give an empty folder (or remove the old keys)")
    folder.mkdir(parents=True, exist_ok=True)
    now = datetime.datetime.now(datetime.timezone.utc)

    def name(common: str) -> x509.Name:
        return x509.Name([x509.NameAttribute(NameOID.ORGANIZATION_NAME, "hil"),
                          x509.NameAttribute(NameOID.COMMON_NAME, common)])

    def certificate(subject, public_key, issuer, signing_key, is_ca: bool):
        builder = (x509.CertificateBuilder().subject_name(subject).issuer_name(issuer)
                   .public_key(public_key).serial_number(x509.random_serial_number())
                   .not_valid_before(now - datetime.timedelta(minutes=5))
                   .not_valid_after(now + datetime.timedelta(days=VALID_DAYS))
                   .add_extension(x509.BasicConstraints(ca=is_ca, path_length=None),
                                  critical=True))
        if is_ca:
            builder = builder.add_extension(x509.KeyUsage(
                digital_signature=True, key_cert_sign=True, crl_sign=True,
                content_commitment=False, key_encipherment=False, data_encipherment=False,
                key_agreement=False, encipher_only=False, decipher_only=False), critical=True)
        else:
            builder = builder.add_extension(x509.ExtendedKeyUsage(
                [x509.ExtendedKeyUsageOID.SERVER_AUTH, x509.ExtendedKeyUsageOID.CLIENT_AUTH]),
                critical=False)
        return builder.sign(signing_key, hashes.SHA256())

    def write(path: Path, data: bytes, private: bool) -> Path:
        path.write_bytes(data)
        if private:
            path.chmod(0o600)
        return path

    def key_bytes(key) -> bytes:
        return key.private_bytes(serialization.Encoding.PEM,
                                 serialization.PrivateFormat.PKCS8,
                                 serialization.NoEncryption())

    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca_name = name("hil CA")
    ca = certificate(ca_name, ca_key.public_key(), ca_name, ca_key, is_ca=True)
    written = [write(folder / CA_KEY, key_bytes(ca_key), True),
               write(folder / CA_CERTIFICATE, ca.public_bytes(serialization.Encoding.PEM), False)]
    for role in ROLES:
        key = ec.generate_private_key(ec.SECP256R1())
        issued = certificate(name(role), key.public_key(), ca_name, ca_key, is_ca=False)
        written += [write(folder / f"{role}.key", key_bytes(key), True),
                    write(folder / f"{role}.pem", issued.public_bytes(serialization.Encoding.PEM),
                          False)]
    return written
