"""The emulated environment: the 802.15.4 air (and later the light, the world and chaos) behind a zenoh router."""
