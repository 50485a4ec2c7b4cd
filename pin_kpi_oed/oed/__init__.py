"""Optimum experimental design maths: identifiability, covariances (eq. 19), criteria, pool selection, certificates."""
