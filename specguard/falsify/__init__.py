"""Falsifying trained agents: start spaces, the guided search for failing starts, and its reports."""
