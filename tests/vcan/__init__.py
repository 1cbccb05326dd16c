"""Harness for the tests over real SocketCAN: the host's vcan0, or a user-mode Linux guest."""
