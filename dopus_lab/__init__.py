"""dopus-lab: the lab beside the product.

Benchmarks and measurements of the generated solvers, kept apart from the code generator
(:mod:`dopus_codegen`): the timing of ``dopus-gen bench`` (:mod:`.bench`, and its timing
process :mod:`.timing`, which loads only compiled libraries), the comparison with acados
(:mod:`.acados_compare`, :mod:`.acados_export`, and :mod:`.acados_ocp`, which runs in
acados' own environment) and the firmware measurement report on emulated Cortex-M cores
(:mod:`.firmware`). The lab uses the product's public pieces; the product never imports
the lab: the lab adds its verbs (``bench``, ``firmware-report``) to ``dopus-gen`` through
the entry points of the group ``dopus_codegen.verbs`` (:mod:`.cli`).
"""
