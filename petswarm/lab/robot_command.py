"""A robot process's options as a typed dataclass (``RobotOptions``), the command line that starts such a process
(``RobotOptions.argv``), and the ``RobotConfig`` they describe (``robot_config``).

Every run builds its robots as ``RobotOptions``: a model-time run turns them straight into ``RobotConfig``s, a
process run (wall clock or lockstep) starts ``petswarm robot`` with their ``argv()``, which the CLI (``cli/robot.py``)
parses back into the same ``RobotOptions``. So both kinds of run build the same robots from the same options.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from typing import TYPE_CHECKING

from petswarm.profiles import DEFAULT_PROFILE

if TYPE_CHECKING:
    from petswarm.controllers.surround import SurroundConfig
    from petswarm.robot import RobotConfig

NODE_CLOCKS = ("wall", "lockstep")
"""The clocks a node process (robot, user) runs on: a lockstep node waits for its hub's grants."""
DEFAULT_HUB = "tcp/127.0.0.1:7447"
"""The hub endpoint a node connects to when none is given."""


@dataclass(frozen=True)
class RobotOptions:
    """The options of one robot process (``petswarm robot``), field for field as its command line names them
    (``--ping-interval`` is ``ping_interval``), with the same defaults. Transport security (``--tls-*``) is not
    here: it belongs to the process's zenoh session, not to the robot."""

    id: int
    """Robot id 1-65533, also its short address; 0 claims the lowest free one at the hub (``--id auto``)."""
    hub: str = DEFAULT_HUB
    world: str = "default"
    clock: str = "wall"
    """``wall`` or ``lockstep`` (a process's clock; a model-time run ignores it)."""
    pan: int = 0x1000
    channel: int = 11
    pos: tuple[float, float] | None = None
    """Position x, y in metres; None: the default grid place of the id."""
    ping_interval: float = 0.0
    seed: int = 0
    user: int = 0
    region_rssi: int = -70
    step_deadline: float | None = None
    """None: the profile's, else ``StepTiming``'s default."""
    step_retries: int = 5
    record: str | None = None
    profile: str = DEFAULT_PROFILE
    link_key: str | None = None
    """Path of a file with the 802.15.4 network key (32 hex digits); None: link security off."""
    link_mic: int = 4
    heading: float = 0.0
    ir_estimator: str = "lsq"
    ir_slot: float = 0.1
    ir_deadline: float = 0.05
    ir_retries: int = 3
    protocol: str = "paper"
    formation: str = "swarm"
    surround_human: str = "user"
    surround_config: SurroundConfig | None = None
    """The surround law's settings; None: the documented gains."""

    def __post_init__(self) -> None:
        # the numbers take the types the command line gives them, so that options built in code and the same
        # options read back from their argv() are equal (an int 1 and a float 1.0 log differently)
        for name in ("ping_interval", "heading", "ir_slot", "ir_deadline"):
            object.__setattr__(self, name, float(getattr(self, name)))
        if self.step_deadline is not None:
            object.__setattr__(self, "step_deadline", float(self.step_deadline))
        if self.pos is not None:
            x, y = self.pos
            object.__setattr__(self, "pos", (float(x), float(y)))

    def argv(self) -> list[str]:
        """The ``petswarm robot`` command line (without the program) of a process with these options: the id, hub
        and world always, every other option only when it is not its default."""
        argv = ["robot", "--id", str(self.id), "--hub", self.hub, "--world", self.world]
        defaults = RobotOptions(id=self.id)
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name in ("id", "hub", "world") or value == getattr(defaults, f.name):
                continue
            flag = "--" + f.name.replace("_", "-")
            if f.name == "pos":
                argv.append(f"{flag}={value[0]!r},{value[1]!r}")  # '=': a negative x is not taken for an option
            elif f.name == "surround_config":
                argv += [flag, json.dumps(_changed_settings(value))]
            elif f.name == "heading":
                argv.append(f"{flag}={value!r}")
            else:
                argv += [flag, str(value)]
        return argv


def _changed_settings(config: SurroundConfig) -> dict[str, object]:
    """The settings of ``config`` that differ from the documented gains (what ``--surround-config`` takes)."""
    from petswarm.controllers.surround import SurroundConfig

    default = SurroundConfig().to_dict()
    return {key: value for key, value in config.to_dict().items() if value != default[key]}


def robot_config(options: RobotOptions) -> RobotConfig:
    """The robot ``options`` describe: what a ``petswarm robot`` process runs, and how a model-time run builds
    its robots."""
    from petswarm.controllers.surround import SurroundConfig
    from petswarm.controllers.surround_pilot import SurroundDriverConfig
    from petswarm.managers.exchange import StepTiming
    from petswarm.managers.formation import FormationConfig
    from petswarm.managers.relative_location import TokenConfig
    from petswarm.profiles import robot_profile
    from petswarm.robot import RobotConfig
    from radio_hub.interface import read_key_file

    o = options
    profile = robot_profile(o.profile)
    deadline = o.step_deadline if o.step_deadline is not None else profile.step_deadline_s
    timing = StepTiming(StepTiming().deadline_s if deadline is None else deadline, o.step_retries)
    formation = FormationConfig(protocol=o.protocol, step=timing, min_rssi_dbm=o.region_rssi)
    return RobotConfig(
        robot_id=o.id,
        endpoint=o.hub,
        world=o.world,
        pan_id=o.pan,
        channel=o.channel,
        position=o.pos,
        ping_interval=o.ping_interval,
        seed=o.seed,
        user=o.user,
        formation=formation,
        token=TokenConfig(slot_s=o.ir_slot, step=StepTiming(o.ir_deadline, o.ir_retries), estimator=o.ir_estimator),
        heading_deg=o.heading,
        record=o.record,
        formation_mode=o.formation,
        surround=SurroundDriverConfig(law=o.surround_config or SurroundConfig(), human_id=o.surround_human),
        profile=o.profile,
        link_key=read_key_file(o.link_key).hex() if o.link_key else None,
        link_mic=o.link_mic,
    )
