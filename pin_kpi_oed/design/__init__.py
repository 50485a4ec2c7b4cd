"""KPI optimum experimental design solved by IPOPT (eq. 24)."""
