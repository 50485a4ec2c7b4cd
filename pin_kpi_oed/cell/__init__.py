"""The work cell: robot and obstacle capsules, tracker, constraints (collision, incidence), feasibility check."""
