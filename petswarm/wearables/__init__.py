"""The user's side: the emulated user process (``user``: belt + watch walking a scripted path; ``plan``, the
path and requests a scenario gives it), the belt's IMU and activity recognition, the watch's gestures, the LF
location of the user, and the link between a robot and its user (``user_link``).
"""
