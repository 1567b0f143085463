"""Each node declares exactly its schema, and every writable parameter is checked completely before it is applied.

In-process (rclpy's own ``set_parameters`` path, range checks included): each writable parameter of each node set
to hostile values is refused with a reason or accepted inside its declared range, and the node works on; the
range ends are accepted unless another setting of the node forbids it (and the refusal names that setting).
test/launching/test_param_fuzz.py does the same through the real ``ros2 param set`` against running nodes.
"""

from __future__ import annotations

import math

import pytest

from tactile_descriptors_ros.params import SCHEMAS

pytestmark = pytest.mark.ros

#: What a careless user or a hostile domain sends: every type, the number edges, empty and long strings.
HOSTILE = (0, -1, 2**62, 1e-300, 1e300, float("nan"), float("inf"), -float("inf"), "", "window", "x" * 100_000)


def make_node(executable: str, ros_context, tmp_path):
    from rclpy.parameter import Parameter

    if executable == "window_node":
        from tactile_descriptors_ros.nodes.window_node import WindowNode

        return WindowNode(context=ros_context, parameter_overrides=[Parameter("robot", value="shadow_hand"),
                                                                    Parameter("body_parts", value=["index"])])
    if executable == "contact_node":
        from tactile_descriptors_ros.nodes.contact_node import ContactNode

        return ContactNode(context=ros_context, parameter_overrides=[Parameter("robot", value="nao")])
    if executable == "tf_publisher":
        pytest.importorskip("tf2_msgs", reason="no tf2_msgs (not on PyPI; make setup builds it with the ros2 CLI)")
        from tactile_descriptors_ros.nodes.tf_publisher import TfPublisher

        return TfPublisher(context=ros_context, parameter_overrides=[Parameter("robot", value="nao")])
    if executable == "classifier_node":
        from tactile_descriptors_ros.nodes.classifier_node import ClassifierNode

        return ClassifierNode(context=ros_context, parameter_overrides=[
            Parameter("load_model", value=False), Parameter("model_path", value=str(tmp_path / "model.json"))])
    if executable == "biotac_driver":
        from tactile_descriptors_ros.nodes.biotac_driver import BiotacDriver as cls

        robot = "shadow_hand"
    else:
        from tactile_descriptors_ros.nodes.skin_driver import SkinDriver as cls

        robot = "nao"
    return cls(context=ros_context, parameter_overrides=[Parameter("robot", value=robot),
                                                         Parameter("transport", value="loopback")])


@pytest.fixture(params=sorted(SCHEMAS))
def node(request, ros_context, tmp_path):
    n = make_node(request.param, ros_context, tmp_path)
    try:
        yield n
    finally:
        close = getattr(n, "close", None)
        if close is not None:
            close()
        n.destroy_node()


_ROS_OWN = {"use_sim_time", "start_type_description_service"}


def test_the_node_declares_exactly_its_schema(node):
    from rclpy.parameter import Parameter

    from tactile_descriptors_ros.nodes.parameters import parameter_descriptor

    schema = node.params.schema
    names = sorted(set(node.list_parameters([], 0).names) - _ROS_OWN)
    assert names == sorted(schema.names)
    for name, got in zip(names, node.describe_parameters(names)):
        p, want = schema[name], parameter_descriptor(schema[name])
        assert Parameter.Type(got.type).name.lower() == p.type, name
        assert (got.read_only, got.description, got.additional_constraints) == \
            (want.read_only, want.description, want.additional_constraints), name
        assert list(got.floating_point_range) == list(want.floating_point_range), name
        assert list(got.integer_range) == list(want.integer_range), name


def _set(node, name, value):
    """``set_parameters`` as the parameter service calls it; the result and the value in force after."""
    from rclpy.parameter import Parameter

    result = node.set_parameters([Parameter(name, value=value)])[0]
    return result, node.get_parameter(name).value


def _alive(node) -> None:
    """The node still does its work: diagnostics report, and the node's own periodic work runs."""
    statuses = node.diagnostics.statuses()
    assert statuses and all("diagnostic task failed" not in s.message for s in statuses), \
        [s.message for s in statuses]
    order = getattr(node, "order", None)
    if order is not None:
        import time

        order.poll(time.monotonic())


def test_hostile_values_are_refused_with_a_reason_or_accepted_in_range(node):
    for p in node.params.schema.tunable():
        before = node.get_parameter(p.name).value
        for value in HOSTILE:
            result, now = _set(node, p.name, value)
            if result.successful:
                assert p.range is None or p.range[0] <= now <= p.range[1], (p.name, value, now)
                assert not (isinstance(now, float) and not math.isfinite(now)), (p.name, value)
                assert node.params[p.name] == now, (p.name, value)
            else:
                assert result.reason, (p.name, value)
                assert now == before, (p.name, value)
            _alive(node)
            r = node.set_parameters([__import__("rclpy.parameter", fromlist=["Parameter"]).Parameter(
                p.name, value=before)])[0]
            assert r.successful, (p.name, before, r.reason)


def test_the_declared_range_is_what_a_set_accepts(node):
    """Both ends of every writable number's range are accepted, unless the node's other settings forbid it, and
    then the refusal names the other setting; a step beyond an end is refused."""
    from rclpy.parameter import Parameter

    schema = node.params.schema
    for p in schema.tunable():
        if p.range is None:
            continue
        before = node.get_parameter(p.name).value
        others = [n for n in schema.names if n != p.name]
        for end in p.range:
            result, _ = _set(node, p.name, end)
            if not result.successful:
                named = result.reason.replace(p.name, "")
                assert any(o in named for o in others), (p.name, end, result.reason)
            node.set_parameters([Parameter(p.name, value=before)])
        lo, hi = p.range
        step = max(1, abs(hi) * 1e-3) if p.type == "integer" else max(1e-3, abs(hi) * 1e-3)
        for beyond in (lo - step, hi + step):
            value = int(beyond) if p.type == "integer" else float(beyond)
            result, now = _set(node, p.name, value)
            assert not result.successful and now == before, (p.name, value)
