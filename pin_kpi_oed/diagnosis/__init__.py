"""Sim-to-real gap diagnosis: where the residual lies, which effect causes it, how far it shrinks."""
