"""``--secure``: mutual TLS between hil's processes and an access policy by role.

``hil keys init DIR`` makes a certificate authority and one certificate per role
(:data:`ROLES`), each named by its role in its Common Name. A process started with
``--secure DIR`` speaks TLS only (``tcp/`` endpoints become ``tls/``), shows its role's
certificate and accepts only peers whose certificate the same CA signed (mutual TLS: a
client of another CA cannot connect).

Every process enforces the policy on what it receives (Zenoh's access control, ingress,
subjects by certificate Common Name), so a message is refused by the process that would act
on it; and on what it sends: queries go to the drives and the controller only, so an
operator's goal never reaches another client, even a peer linked a moment ago. Peers link
directly (no relay, ``hil.zenoh_session``), so the certificate a process checks is the
sender's own. The rights are allow-lists, deny by default: Zenoh applies a rule
to a message whose key expression the rule's key expressions include, so a wider expression
or a wildcard (``**``, ``hil/**``, ``<key>$*``, ``hil/<robot>/*``) is inside no allow rule of
a narrower right and is denied (a deny rule on an exact key would let it through: issue 43).
A certificate of the CA with any other name matches no subject and is refused everything.

- ``drives`` (``hil sim``) and ``controller`` (``hil control``): everything;
- ``operator`` (``hil send``, ``hil reset``, ``hil controllers``, ``hil up``'s own session):
  the controller's commands (an action's goals, cancels and results, the fault reset, a
  controller switch, a forward controller's commands) as queries of those keys, subscriptions and liveliness under ``hil/``; no CAN frame, nothing published;
- ``observer`` (``hil viz``): subscriptions, liveliness, goal results and the controllers'
  list under ``hil/``, its own liveliness token, and the receipts of its CAN log
  (:data:`RECEIPT_KEYS`: the one query a client is sent, answered by the one queryable it
  may declare); no frame, no goal, no cancel, no reset, nothing published.

docs/security.md has the threat model. The certificates carry no host names, and names are
not verified on connect: a peer is whoever holds a key the CA signed, wherever it connects
from.
"""

from __future__ import annotations

import datetime
import json
from dataclasses import dataclass
from pathlib import Path

from hil.errors import HilError

#: the roles and the commands that take each
ROLES = {"drives": "hil sim", "controller": "hil control",
         "operator": "hil send, hil reset, hil controllers",
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
COMMAND_KEYS = ["hil/*/**/send_goal", "hil/*/**/cancel_goal", "hil/*/reset_faults",
                "hil/*/controller_manager/switch_controller", "hil/*/*/commands"]
#: the results of an action's goals and the controllers' list: reads, queried
RESULT_KEYS = ["hil/*/**/get_result", "hil/*/controller_manager/list_controllers"]
#: what every role may read: subscriptions and liveliness anywhere under hil/
READ_KEYS = ["hil/**"]
EVERY_MESSAGE = ["put", "delete", "declare_subscriber", "query", "reply", "declare_queryable",
                 "liveliness_token", "liveliness_query", "declare_liveliness_subscriber"]
READ_MESSAGES = ["declare_subscriber", "liveliness_query", "declare_liveliness_subscriber"]
#: what a process sends an operator or an observer: all but queries, for they serve none. A
#: peer that has just linked is sent queries before its declarations are known (Zenoh's
#: discovery window), so without this an observer's queryable on a command key could be asked
#: an operator's goal (never answered: its reply is refused on ingress, but the goal is seen
#: and the operator waits for the query's end)
TO_CLIENT_MESSAGES = [m for m in EVERY_MESSAGE if m != "query"]
#: where each session with a CAN log's buses answers which frame of each sender it heard
#: (``<key>/<session id>``), asked by lock-step senders before they close
#: (:mod:`hil.can.zenoh_receipts`)
RECEIPTS_KEY = "hil/can-receipts"
#: the one query a client (an observer's log) is sent, answered by the one queryable it may
#: declare; a wrong answer can only hold a sender's close up to its LINGER
RECEIPT_KEYS = [f"{RECEIPTS_KEY}/*"]


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
    """Zenoh's access_control section: the roles' rights as allow-lists (module doc),
    enforced on what a process receives; what it sends is the receiver's to judge."""
    def rule(rule_id, messages, keys, flows=("ingress",)):
        return {"id": rule_id, "permission": "allow", "messages": messages,
                "key_exprs": keys, "flows": list(flows)}

    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": [
            rule("send anything", EVERY_MESSAGE, ["**"], ("egress",)),
            rule("send a client", TO_CLIENT_MESSAGES, ["**"], ("egress",)),
            rule("anything", EVERY_MESSAGE, ["**"]),
            rule("read", READ_MESSAGES, READ_KEYS),
            rule("results", ["query"], RESULT_KEYS),
            rule("commands", ["query"], COMMAND_KEYS),
            rule("viewer's token", ["liveliness_token"], ["hil/*/viz"]),
            rule("receipts asked", ["query"], RECEIPT_KEYS, ("egress",)),
            rule("receipts answered", ["declare_queryable", "reply"], RECEIPT_KEYS),
        ],
        "subjects": [{"id": role, "cert_common_names": [role]} for role in ROLES],
        "policies": [
            {"rules": ["send anything"], "subjects": ["drives", "controller"]},
            {"rules": ["send a client"], "subjects": ["operator", "observer"]},
            {"rules": ["anything"], "subjects": ["drives", "controller"]},
            {"rules": ["read", "results", "commands"], "subjects": ["operator"]},
            {"rules": ["read", "results", "viewer's token", "receipts answered",
                       "receipts asked"], "subjects": ["observer"]},
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
