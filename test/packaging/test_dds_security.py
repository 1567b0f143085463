"""What docs/security.md says of ROS 2 security here: the Fast DDS of the wheels has no security plugins, so a
node given an SROS2 enclave (ROS_SECURITY_ENABLE=true) cannot start, in either strategy.

The enclave is made with openssl the way ``ros2 security create_enclave`` lays it out (sros2 is not among the
wheels): a CA, an identity certificate, and signed governance and permissions documents.
"""

from __future__ import annotations

import os
import random
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.ros

_REPO = Path(__file__).resolve().parents[2]

_GOVERNANCE = """<?xml version="1.0" encoding="UTF-8"?>
<dds><domain_access_rules><domain_rule><domains><id_range><min>0</min><max>230</max></id_range></domains>
<allow_unauthenticated_participants>false</allow_unauthenticated_participants>
<enable_join_access_control>true</enable_join_access_control>
<discovery_protection_kind>ENCRYPT</discovery_protection_kind>
<liveliness_protection_kind>ENCRYPT</liveliness_protection_kind><rtps_protection_kind>SIGN</rtps_protection_kind>
<topic_access_rules><topic_rule><topic_expression>*</topic_expression>
<enable_discovery_protection>true</enable_discovery_protection>
<enable_liveliness_protection>true</enable_liveliness_protection>
<enable_read_access_control>true</enable_read_access_control>
<enable_write_access_control>true</enable_write_access_control>
<metadata_protection_kind>ENCRYPT</metadata_protection_kind><data_protection_kind>ENCRYPT</data_protection_kind>
</topic_rule></topic_access_rules></domain_rule></domain_access_rules></dds>
"""

_PERMISSIONS = """<?xml version="1.0" encoding="UTF-8"?>
<dds><permissions><grant name="/classifier_node"><subject_name>CN=classifier_node</subject_name>
<validity><not_before>2020-01-01T00:00:00</not_before><not_after>2040-01-01T00:00:00</not_after></validity>
<allow_rule><domains><id_range><min>0</min><max>230</max></id_range></domains>
<publish><topics><topic>*</topic></topics></publish><subscribe><topics><topic>*</topic></topics></subscribe>
</allow_rule><default>DENY</default></grant></permissions></dds>
"""


def _enclave(keystore: Path) -> None:
    enclave = keystore / "enclaves" / "classifier_node"
    enclave.mkdir(parents=True)

    def ssl(*args: str) -> None:
        subprocess.run(["openssl", *args], cwd=keystore, check=True, capture_output=True)

    ssl("ecparam", "-name", "prime256v1", "-genkey", "-noout", "-out", "ca.key.pem")
    ssl("req", "-new", "-x509", "-key", "ca.key.pem", "-out", "ca.cert.pem", "-days", "2", "-subj", "/CN=test_ca")
    ssl("ecparam", "-name", "prime256v1", "-genkey", "-noout", "-out", str(enclave / "key.pem"))
    ssl("req", "-new", "-key", str(enclave / "key.pem"), "-out", "id.csr", "-subj", "/CN=classifier_node")
    ssl("x509", "-req", "-in", "id.csr", "-CA", "ca.cert.pem", "-CAkey", "ca.key.pem", "-CAcreateserial",
        "-out", str(enclave / "cert.pem"), "-days", "2")
    for name in ("identity_ca.cert.pem", "permissions_ca.cert.pem"):
        shutil.copy(keystore / "ca.cert.pem", enclave / name)
    for name, text in (("governance", _GOVERNANCE), ("permissions", _PERMISSIONS)):
        (keystore / f"{name}.xml").write_text(text)
        ssl("smime", "-sign", "-in", f"{name}.xml", "-text", "-out", str(enclave / f"{name}.p7s"),
            "-signer", "ca.cert.pem", "-inkey", "ca.key.pem")


@pytest.mark.parametrize("strategy", ["Permissive", "Enforce"])
def test_a_node_with_an_sros2_enclave_cannot_start_on_these_wheels(tmp_path, strategy):
    if shutil.which("openssl") is None:
        pytest.skip("openssl is needed to make the enclave")
    keystore = tmp_path / "keystore"
    keystore.mkdir()
    _enclave(keystore)
    env = {**os.environ, "ROS_SECURITY_ENABLE": "true", "ROS_SECURITY_STRATEGY": strategy,
           "ROS_SECURITY_KEYSTORE": str(keystore), "ROS_DOMAIN_ID": str(random.randint(1, 100)),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "PYTHONPATH": os.pathsep.join(p for p in (str(_REPO), os.environ.get("PYTHONPATH", "")) if p)}
    out = subprocess.run([sys.executable, "-m", "tactile_descriptors_ros.nodes.classifier_node", "--ros-args",
                          "--enclave", "/classifier_node", "-p", f"model_path:={tmp_path / 'model.json'}"],
                         env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode != 0
    assert "This Fast DDS version doesn't have the security libraries" in out.stderr, out.stderr[-2000:]
