"""Small algorithms that probe the lifecycle contract (used by tests/core and tests/testing)."""

from swarmbox.api import DroneAlgorithm, GroundAlgorithm, Setpoint, Stage


class NumberedGround(GroundAlgorithm):
    """Sends ``n_tasks`` numbered reliable tasks to every drone from ``prep_once``; marks ``ground_tick``
    with the tick it saw on each hook's first call."""

    def prep_once(self, ctx):
        n = int(ctx.params.get("n_tasks", 40))
        ctx.mark("ground_prep_once", tick=ctx.tick)
        for drone in sorted(ctx.reports):
            for k in range(n):
                ctx.send_task(drone, code=k, data=str(k))

    def prep_loop(self, ctx):
        if not hasattr(self, "first_prep_loop"):
            self.first_prep_loop = ctx.tick
            ctx.mark("ground_prep_loop", tick=ctx.tick)


class StatefulDrone(DroneAlgorithm):
    """Sets its task list up in ``prep_once`` and insists on tasks arriving in order, once each.

    Any violation raises (so the run fails with the hook's name); prep completes once every task
    has arrived; EXECUTION completes at once (the drone arms, then lands).
    """

    def prep_once(self, ctx):
        self.received = []
        ctx.mark("drone_prep_once", tick=ctx.tick)

    def on_task(self, ctx, task):
        if ctx.stage is not Stage.PREPARATION:
            raise AssertionError(f"task {task.data} delivered in {ctx.stage.name}")
        expected = len(self.received)
        if task.code != expected:
            raise AssertionError(f"task {task.code} delivered, expected {expected} (got {self.received})")
        self.received.append(task.code)

    def prep_complete(self, ctx):
        return len(self.received) >= int(ctx.params.get("n_tasks", 40)) and ctx.state.ready_to_arm

    def exec_once(self, ctx):
        ctx.mark("tasks", received=len(self.received))

    def exec_loop(self, ctx):
        return None

    def exec_complete(self, ctx):
        return True


class SlowPrepGround(GroundAlgorithm):
    """Holds PREPARATION open for 3 s with ``prep_complete``."""

    def prep_complete(self, ctx):
        return ctx.stage_time_s >= 3.0


class HoverHere(DroneAlgorithm):
    def exec_loop(self, ctx):
        n, e, _ = ctx.home_ned_m
        return Setpoint.position(n, e, -2.0)

    def exec_complete(self, ctx):
        return ctx.stage_time_s > 2.0


class BadSetpointDrone(DroneAlgorithm):
    """Hovers above home, but at fixed ticks asks for a NaN, a 1.5 km jump and a point 600 m out."""

    def exec_loop(self, ctx):
        n, e, _ = ctx.home_ned_m
        k = ctx.tick
        if k == 40:
            return Setpoint.position(float("nan"), e, -2.0)
        if k == 41:
            return Setpoint.position(n + 1500.0, e, -2.0)
        if k == 42:
            return Setpoint.position(n, e + 600.0, -2.0)
        if k == 43:
            return Setpoint.position(n, e, -300.0)
        return Setpoint.position(n, e, -2.0)

    def exec_complete(self, ctx):
        return ctx.stage_time_s > 2.0


class TwoSuccessorsDrone(HoverHere):
    """Drone 0 advertises two fallback superiors, 3 then 1, to its inferiors."""

    def successors(self, ctx):
        return (3, 1) if ctx.id == 0 else (ctx.superior,)

    def exec_complete(self, ctx):
        return ctx.stage_time_s > 8.0


class ProximityDrone(HoverHere):
    """Marks, once a second in EXECUTION, which drones the ground reported close to it."""

    def exec_loop(self, ctx):
        if ctx.tick % 40 == 0:
            ctx.mark("near", ids=sorted(d.drone_id for d in ctx.proximity))
        return super().exec_loop(ctx)


class ReportWatchingGround(GroundAlgorithm):
    """Reacts to its inferiors' Reports (``on_report``): marks every 25th Report of each drone with what
    it said, and sends the drone a numbered task each time."""

    def on_report(self, ctx, report):
        seen = self.__dict__.setdefault("seen", {})
        seen[report.id] = seen.get(report.id, 0) + 1
        if seen[report.id] % 25 == 0:
            ctx.mark("report_seen", drone=report.id, n=seen[report.id], stage=str(report.stage),
                     complete=report.complete, pos=[round(x, 6) for x in report.pos_ned_m])
            ctx.send_task(report.id, code=seen[report.id])
