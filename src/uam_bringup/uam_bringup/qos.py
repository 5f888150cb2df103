"""rclpy QoS profiles of the contract (:mod:`uam_contract.names` holds them as plain data)."""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from uam_contract import names as contract
from uam_contract.qos_spec import QosSpec


def profile(spec: QosSpec) -> QoSProfile:
    """The rclpy QoSProfile of a contract QosSpec (history, depth, reliability, durability)."""
    return QoSProfile(history=HistoryPolicy[spec.history.upper()], depth=int(spec.depth),
                      reliability=ReliabilityPolicy[spec.reliability.upper()],
                      durability=DurabilityPolicy[spec.durability.upper()])


QOS_LATCHED = profile(contract.QOS_LATCHED)
QOS_STREAM = profile(contract.QOS_STREAM)
QOS_CLOCK = profile(contract.QOS_CLOCK)
QOS_REQUESTS = profile(contract.QOS_REQUESTS)
QOS_CONSTRAINTS = profile(contract.QOS_CONSTRAINTS)
