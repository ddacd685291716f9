//! Shared helpers for robcal's host tests: independent batch references.
