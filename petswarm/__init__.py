"""The robot and wearable side of petswarm: swarm middleware managers, controllers, the robot process."""
