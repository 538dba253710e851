"""The compiled FHOCP kernel: its C template (the ``*.c`` files beside this one) and the Python
that generates, builds, loads and checks it (:mod:`~controllers.kernel.compiled_kernel`,
:mod:`~controllers.kernel.kernel_lib`), its interface types defined once for C and Python
(:mod:`~controllers.kernel.kernel_abi`), its SQP (:mod:`~controllers.kernel.kernel_sqp`) and the
C build helper (:mod:`~controllers.kernel.cbuild`)."""
