"""Managed (lifecycle) nodes of the graph: what rclpy.lifecycle leaves to the node
(docs/graph.md, The map learner's lifecycle).

A node whose state needs configuring and a clean end (the map learner's map) is an
``rclpy.lifecycle.LifecycleNode`` (ROS 2 managed nodes, as in ros2/demos ``lifecycle_py``):
``unconfigured -> configure -> inactive -> activate -> active`` and back (``deactivate``,
``cleanup``), ``shutdown`` from each of them to ``finalized``; ``ros2 lifecycle get/set``
drives it through its ``~/change_state`` and ``~/get_state`` services.

* :data:`LIFECYCLE_SPECS`: ``autostart`` (default true), the node configures and activates
  itself once it is built, so ``ros2 run``, ``ros2 launch``, ``./tmgwr up`` and the composed
  graph start stepping by themselves; false leaves it unconfigured for a manager
  (``ros2 lifecycle set``, a launch file's ChangeState events, Nav2's lifecycle_manager),
  what Nav2's ``autostart: false`` means.
* :func:`autostart`: configure then activate, raising ValueError with the node's reason
  when a transition fails (the node then stops at start with exit code 2, as before).
* :func:`refuse_invalid_transitions`: rclpy raises out of its ``change_state`` service for
  a transition the current state does not have (a raw ``ros2 service call`` with another
  id), which would end the node; here it is refused (``success: false``) and logged.
* :func:`end`: the node's end once spinning stopped (Ctrl-C, SIGTERM, the graph finished):
  the ``shutdown`` transition from whichever primary state it is in, so its
  ``on_shutdown`` runs (the learner saves its map); nothing when already finalized.

Only public rclpy API is used. rclpy 7.1.6 (the Jazzy wheels) gives ``LifecycleNode`` the
``trigger_*`` methods but no getter of the current state (rclcpp has
``get_current_state()``; rclpy's own ``trigger_shutdown`` reads the private
``_state_machine``), and no way to keep ``change_state`` from raising. Both go through the
node's own lifecycle services instead, which are public: :attr:`rclpy.node.Node.services`
holds them (``LifecycleNodeMixin`` adds them there), and a :class:`rclpy.service.Service`'s
``callback`` is a public attribute that the executors call. :func:`state_of` asks the
``~/get_state`` handler (what ``ros2 lifecycle get`` gets), in process.
"""

from __future__ import annotations

from tmgwr_common.params import Param

#: The parameter of every managed node (declared once, here).
LIFECYCLE_SPECS = (
    Param("autostart", True, "configure and activate this managed node as soon as it starts "
          "(false: it waits unconfigured for `ros2 lifecycle set` or a lifecycle manager)"),
)

PRIMARY = ("unconfigured", "inactive", "active", "finalized")


def lifecycle_service(node, name: str):
    """The node's own lifecycle service ``~/NAME`` (``change_state``, ``get_state``, ...),
    found among :attr:`Node.services` by its fully qualified name."""
    full = f"{node.get_fully_qualified_name().rstrip('/')}/{name}"
    for service in node.services:
        if service.srv_name == full:
            return service
    raise LookupError(f"{node.get_fully_qualified_name()} has no lifecycle service {full}")


def state_of(node) -> str:
    """The label of ``node``'s current lifecycle state (``active``, ``inactive``, ...): the
    answer of its ``~/get_state`` service, asked in process (rclpy 7.1.6 has no public
    getter; module docstring)."""
    from lifecycle_msgs.srv import GetState
    service = lifecycle_service(node, "get_state")
    return service.callback(GetState.Request(), GetState.Response()).current_state.label


def _ok(result) -> bool:
    from rclpy.lifecycle import TransitionCallbackReturn
    return result == TransitionCallbackReturn.SUCCESS


def autostart(node, why: str = "") -> None:
    """Configure, then activate ``node``; ValueError naming the transition and ``why`` (the
    node's last refusal) when one fails."""
    for name, trigger in (("configure", node.trigger_configure),
                          ("activate", node.trigger_activate)):
        result = trigger()
        if not _ok(result):
            reason = getattr(node, "refusal", "") or why or result.to_label()
            raise ValueError(f"{node.get_name()}: {name} failed: {reason}")


def refuse_invalid_transitions(node) -> None:
    """Wrap ``node``'s ``~/change_state`` service: a transition the current state does not
    have is answered ``success: false`` (and logged) instead of raising in the executor.

    rclpy 7.1.6 raises out of its handler (RCLError from ``trigger_transition_by_id``) for
    a transition id the current state lacks, which ends the node: ros2/rclpy#1209, fixed
    upstream by ros2/rclpy#1319 (catching it in ``__change_state``), not in Jazzy's 7.1.6.
    A transition *label* the state lacks was already answered ``success: false``."""
    service = lifecycle_service(node, "change_state")
    serve = service.callback

    def guarded(req, resp):
        before = state_of(node)
        try:
            return serve(req, resp)
        except RuntimeError as exc:              # rclpy's RCLError: not a valid transition
            node.get_logger().warning(
                f"refused transition {req.transition.id} {req.transition.label!r} from "
                f"{before}: {str(exc).split(',')[0]}")
            resp.success = False
            return resp

    service.callback = guarded


def end(node) -> None:
    """Take ``node`` through ``shutdown`` from its current primary state (its
    ``on_shutdown`` runs); nothing when it is finalized already. RuntimeError when the
    shutdown callback failed (the process then exits 1)."""
    state = state_of(node)
    if state not in PRIMARY or state == "finalized":
        return
    result = node.trigger_shutdown()
    if not _ok(result):
        raise RuntimeError(f"shutdown from {state}: {result.to_label()}"
                           + (f" ({node.refusal})" if getattr(node, "refusal", "") else ""))
