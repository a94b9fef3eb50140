"""Falsifying trained agents: the guided search for failing starts over a start space, and its reports."""
