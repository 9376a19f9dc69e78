"""Start-up compiles every kernel, so that no request ever waits for numba."""

from __future__ import annotations

import subprocess
import sys
import textwrap


def test_warm_up_compiles_every_kernel_a_step_calls() -> None:
    # A fresh interpreter: in this one other tests may have compiled the kernels already.
    probe = textwrap.dedent(
        """
        import importlib, pkgutil
        import app.localization as pkg
        from numba.core.registry import CPUDispatcher
        from app.feedback.narrator import warm_up as warm_up_narrator
        from app.localization.filter import warm_up

        warm_up()
        warm_up_narrator()
        kernels, cold = 0, []
        names = [f"app.localization.{info.name}" for info in pkgutil.iter_modules(pkg.__path__)]
        # The step's kernels outside the engine: the angle wrap, the visibility rows and
        # the narrator's match.
        outside = ["app.maps.geometry", "app.maps.visibility", "app.feedback.narrator"]
        # The map check's enclosure test runs when a map is loaded, never in a step.
        not_in_a_step = {"app.maps.geometry._enclosed_points"}
        for module_name in names + outside:
            module = importlib.import_module(module_name)
            for name, obj in vars(module).items():
                if not isinstance(obj, CPUDispatcher) or obj.__module__ != module.__name__:
                    continue
                if obj.targetoptions.get("inline") == "always":
                    continue  # inlined into its callers, never called on its own
                kernels += 1
                if not obj.signatures and f"{module.__name__}.{name}" not in not_in_a_step:
                    cold.append(f"{module.__name__}.{name}")
        print(kernels, ",".join(cold))
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=600, check=True
    )
    count, cold = done.stdout.split(" ", 1)
    assert int(count) >= 7, done.stdout  # the probe found the kernels
    assert cold.strip() == "", f"not compiled by warm_up: {cold.strip()}"
