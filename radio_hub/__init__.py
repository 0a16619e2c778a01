"""The emulated environment: the 802.15.4 air (and later the light, the world and chaos) behind a zenoh router."""

from radio_hub import determinism  # noqa: F401  (numpy's float paths pinned before numpy loads)
