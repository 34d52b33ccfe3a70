"""The project's infrastructure, shared by :mod:`fmu_models`, :mod:`estimators` and
:mod:`cosim` (it imports none of them but :mod:`fmu_models.errors`):

* :mod:`.checks`: validation of numbers, vectors and covariances, with named errors;
* :mod:`.registry`: the registries behind every extension point, and plugin loading;
* :mod:`.memory`: how much memory one allocation may take (every size cap derives from it);
* :mod:`.files`: files written whole or not at all, private temporary folders;
* :mod:`.interrupts`: SIGTERM handled as Ctrl-C, signals deferred over critical sections;
* :mod:`.compiler`: the C compiler, run interruptibly and leaving nothing behind;
* :mod:`.cache`: the on-disk cache of compiled code;
* :mod:`.codegen`: CasADi's generated C with its ``fmin``/``fmax`` helpers inlined;
* :mod:`.cli`: the one error handler of both command lines (exit statuses, messages).
"""
