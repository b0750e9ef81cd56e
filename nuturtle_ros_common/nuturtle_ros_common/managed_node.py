"""A plain node's code run as a managed (lifecycle) node: the lifecycle plumbing every managed node shares.

A managed variant is ``class ManagedX(ManagedNode, X)`` for a plain node class ``X`` whose constructor is
``Node.__init__`` followed by ``self.build()``: ``build`` reads the parameters, builds the node's objects
and creates its topics, services and timers (ValueError for an invalid parameter). The plain node runs it
at construction; the managed one leaves the node unconfigured and runs the same ``build`` at configure,
so both are one code (ROS 2's node lifecycle, design.ros2.org/articles/node_lifecycle.html):

``configure`` (unconfigured -> inactive)
    ``build()``. A ValueError or OSError (an invalid parameter, a file that cannot be read) is logged as an
    error with its reason, whatever ``build`` made so far is dropped, and the transition FAILS: the node
    stays unconfigured, the process runs on. Any other exception is logged with its traceback and the
    transition ends in ERROR, which drops the same and returns to unconfigured.
``activate`` (inactive -> active)
    Publishers publish, subscription and timer callbacks run.
``deactivate`` (active -> inactive)
    Publishers created in ``build`` are lifecycle publishers and drop what is published while inactive;
    the callbacks of the subscriptions and timers it created return at once (the messages are not taken;
    rclpy's own, such as the /clock of sim time, go on). The node's state is kept, and its services
    answer as in the active state.
``cleanup`` (inactive -> unconfigured)
    Every publisher, subscription, timer, service and client ``build`` created is destroyed and every
    attribute it set is deleted: the state is gone, as before the first configure.
``shutdown`` (from unconfigured, inactive or active -> finalized)
    The same as cleanup, from any state; the node is then ``finalized`` and its process's spin loop ends
    (:func:`nuturtle_ros_common.node_main.run_node`), exit code 0.

Parameters are declared and read in ``build``, so they exist from the first configure on, and are kept
across a cleanup (a parameter declared again at a later configure takes its current value). They can be
changed while the node is unconfigured (after a failed configure or a cleanup: fix the value, configure
again) and are refused with the reason while it is configured: a managed node reads them only at
configure. (Their descriptors are therefore not read-only, unlike the plain node's.)

The bond of nav2's lifecycle manager (a heartbeat on /bond after activation, nav2_util's) is no part of
ROS 2's lifecycle and is not offered: manage these nodes with ``bond_timeout: 0.0`` (docs/robot.md).
"""

from __future__ import annotations

import copy
import traceback
from collections.abc import Callable
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.lifecycle.publisher import LifecyclePublisher
from rclpy.parameter import Parameter

from .node_main import effective_parameters


class ManagedNode(LifecycleNode):
    """The lifecycle plumbing (module docstring); the class after it in the bases provides ``build()``."""

    # while build() runs: what it creates is managed, what it declares is kept across cleanups (a class
    # attribute too: Node.__init__ declares use_sim_time, and may subscribe to /clock, before ours runs)
    _building = False

    def __init__(self, node_name: str, **kwargs: Any) -> None:
        LifecycleNode.__init__(self, node_name, **kwargs)
        self._building = False
        self._active = False
        self._finalized = False
        # what build() declared (kept across cleanups), and the attributes there were before it ran
        self._build_parameters: set[str] = set()
        self._unbuilt: set[str] | None = None
        self._entities_before: dict[str, set[int]] = {}
        self.add_on_set_parameters_callback(self._refuse_while_configured)

    @property
    def configured(self) -> bool:
        """True while ``build()`` has run and was not dropped (inactive or active)."""
        return self._unbuilt is not None

    @property
    def finalized(self) -> bool:
        """True once the node has shut down (lifecycle state finalized): its process has nothing to do."""
        return self._finalized

    # --- transitions -------------------------------------------------------------------------------------

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._unbuilt = set(vars(self))
        self._entities_before = {
            kind: {id(e) for e in entities} for kind, entities in self._entities().items()
        }
        self._building = True
        try:
            self.build()  # type: ignore[attr-defined]  # the plain node's, next in the bases
        except (ValueError, OSError) as error:
            self.get_logger().error(f"configure failed, the node stays unconfigured: {error}")
            self._drop()
            return TransitionCallbackReturn.FAILURE
        except Exception as error:
            self.get_logger().error(
                f"configure raised {type(error).__name__}: {error}\n{traceback.format_exc()}"
            )
            self._drop()
            return TransitionCallbackReturn.ERROR
        finally:
            self._building = False
        self.get_logger().info(f"configured; parameters: {effective_parameters(self)}")
        return super().on_configure(state)

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._active = True
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._active = False
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._drop()
        return super().on_cleanup(state)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._active = False
        self._drop()
        self._finalized = True
        self.get_logger().info("shut down (finalized)")
        return super().on_shutdown(state)

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._active = False
        self._drop()
        self.get_logger().error(f"an error in a transition from {state.label}: back to unconfigured")
        return TransitionCallbackReturn.SUCCESS

    def _drop(self) -> None:
        """Destroy what ``build()`` created and delete the attributes it set (nothing when not built)."""
        if self._unbuilt is None:
            return
        for kind, entities in self._entities().items():
            for entity in entities:
                if id(entity) not in self._entities_before[kind]:
                    self._destroy(kind, entity)
        for name in set(vars(self)) - self._unbuilt:
            delattr(self, name)
        self._unbuilt = None

    def _entities(self) -> dict[str, list[Any]]:
        return {
            "publisher": list(self.publishers),
            "subscription": list(self.subscriptions),
            "timer": list(self.timers),
            "service": list(self.services),
            "client": list(self.clients),
        }

    def _destroy(self, kind: str, entity: Any) -> None:
        if isinstance(entity, LifecyclePublisher):
            self.destroy_lifecycle_publisher(entity)
        else:
            getattr(self, f"destroy_{kind}")(entity)

    # --- what build() creates and declares ---------------------------------------------------------------

    def create_publisher(self, *args: Any, **kwargs: Any) -> Any:
        """A lifecycle publisher when ``build()`` creates it (publishes only while active)."""
        if self._building:
            return self.create_lifecycle_publisher(*args, **kwargs)
        return super().create_publisher(*args, **kwargs)

    def create_subscription(
        self, msg_type: Any, topic: str, callback: Callable[[Any], None], *args, **kwargs
    ):
        """When ``build()`` creates it, a subscription whose ``callback`` runs only while the node is active
        (rclpy's own, such as the /clock of sim time, always run)."""
        return super().create_subscription(msg_type, topic, self._gated(callback), *args, **kwargs)

    def create_timer(self, timer_period_sec: float, callback: Callable[[], None], *args, **kwargs):
        """When ``build()`` creates it, a timer whose ``callback`` runs only while the node is active."""
        return super().create_timer(timer_period_sec, self._gated(callback), *args, **kwargs)

    def _gated(self, callback: Callable[..., None]) -> Callable[..., None]:
        """``callback`` run only while active, for what ``build()`` creates; else ``callback`` itself."""
        if not self._building:
            return callback

        def gated(*args: Any) -> None:
            if self._active:
                callback(*args)

        return gated

    def declare_parameter(
        self,
        name: str,
        value: Any = None,
        descriptor: ParameterDescriptor | None = None,
        ignore_override: bool = False,
    ) -> Parameter:
        """In ``build()``: a parameter declared at an earlier configure keeps its current value; a new one is
        declared changeable (:meth:`_refuse_while_configured` refuses changes while configured)."""
        if not self._building:
            return super().declare_parameter(name, value, descriptor, ignore_override)
        if name in self._build_parameters:
            return self.get_parameter(name)
        changeable = copy.deepcopy(descriptor) if descriptor is not None else ParameterDescriptor()
        changeable.read_only = False
        parameter = super().declare_parameter(name, value, changeable, ignore_override)
        self._build_parameters.add(name)
        return parameter

    def _refuse_while_configured(self, parameters: list[Parameter]) -> SetParametersResult:
        """Changes to the parameters ``build()`` reads are taken only while unconfigured."""
        names = sorted(p.name for p in parameters if p.name in self._build_parameters)
        if names and self.configured:
            reason = (
                f"{', '.join(names)}: read at configure only; change them while the node is unconfigured "
                f"(cleanup first), then configure"
            )
            return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)
