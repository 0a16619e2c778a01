"""The robot and wearable side of petswarm: swarm middleware managers, controllers, the robot process."""

import radio_hub.determinism  # noqa: F401  (numpy's float paths pinned before numpy loads)
