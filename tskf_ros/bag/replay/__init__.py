"""Offline replay of a bag through a node's session, without DDS: replay_offline."""
