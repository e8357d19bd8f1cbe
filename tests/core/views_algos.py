"""Algorithms that reach past the context's contract: writing shared views, tasks to non-inferiors,
markers with objects. Used by tests/core/test_views.py."""

import numpy as np

from swarmbox.api import DroneAlgorithm, GroundAlgorithm, Setpoint


class PlainHover(DroneAlgorithm):
    """Hovers 2 m above home for 1 s of EXECUTION (no typed params)."""

    def exec_loop(self, ctx):
        n, e, _ = ctx.home_ned_m
        return Setpoint.position(n, e, -2.0)

    def exec_complete(self, ctx):
        return ctx.stage_time_s > 1.0


class WritingDrone(PlainHover):
    """Drone 1 writes ``params.write`` (``params`` | ``mission``) in exec_once; the others mark what
    they read (hover_s and drone 0's spawn) at the end of EXECUTION."""

    def exec_once(self, ctx):
        if ctx.id == 1:
            if ctx.params["write"] == "params":
                ctx.params["hover_s"] = 1000.0
            else:
                ctx.mission.initial_positions[0] = (99.0, 99.0, 0.0)

    def exec_loop(self, ctx):
        if ctx.stage_time_s > 0.5 and not getattr(self, "seen", False):
            self.seen = True
            ctx.mark("seen", hover_s=ctx.params["hover_s"], spawn_0=ctx.mission.initial_positions[0])
        return super().exec_loop(ctx)


class TryWritingDrone(PlainHover):
    """Tries every kind of write into its views, catching each; marks how many were refused."""

    def exec_once(self, ctx):
        writes = [lambda: ctx.params.__setitem__("hover_s", 1000.0),
                  lambda: ctx.params.pop("hover_s"),
                  lambda: ctx.mission.initial_positions.__setitem__(0, (9.0, 9.0, 0.0)),
                  lambda: ctx.mission.superiors.clear(),
                  lambda: ctx.mission.values.update({0: (1.0,)}),
                  lambda: ctx.params["nested"]["k"].append(4),
                  lambda: ctx.params["nested"].__setitem__("j", 1)]
        refused = 0
        for write in writes:
            try:
                write()
            except (TypeError, AttributeError):
                refused += 1
        ctx.mark("writes_refused", n=refused, of=len(writes), nested=ctx.params["nested"],
                 hover_s=ctx.params["hover_s"])


class TaskingGround(GroundAlgorithm):
    """In PREPARATION, sends one task to ``params.to`` (a drone id) and marks whether it was sent."""

    def prep_once(self, ctx):
        ctx.mark("task_sent", to=ctx.params["to"], sent=ctx.send_task(int(ctx.params["to"]), code=7))


class MarkingDrone(PlainHover):
    """Marks ``params.mark`` in exec_once: ``numpy`` values, or an ``object``."""

    def exec_once(self, ctx):
        if ctx.params["mark"] == "numpy":
            ctx.mark("values", f32=np.float32(1.5), i64=np.int64(7), arr=np.arange(3), b=np.bool_(True),
                     grid=np.eye(2), nested={"x": (np.float64(0.25), None)})
        else:
            ctx.mark("values", ok=1, o=object())
