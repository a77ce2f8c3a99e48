"""The numpy oracle of the C runtime: the DOPUS iteration (dopus), its QP solver (qp), the
KKT measure (kkt) and the offline NLP solve with IPOPT (offline)."""
