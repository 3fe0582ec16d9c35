"""The experiments: one module each, holding its trial, summary text and command (`command.Command`).

- `plate`: the paper's plate tests, drag and rotate (`PlateTest`, `simulate`)
- `swim`: the two-fin robot swimming (`Swim`, `swim`)
- `user_model`: a user's MJCF model, one joint driven through the medium (`UserModel`; finrft run)
- `intrusion`: a plate pushed down into the medium (`Intrusion`, `intrude`)
- `wheel`: a wheel on a single-wheel rig, its sinkage held or free under a load (`Wheel`, `run_wheel`; finrft wheel)

`REGISTRY` maps each command name to its `Command`; the CLI gives every entry a subcommand and the tests iterate
it. Every module of this package is imported here, and registers its commands as it is (``@register``): a new
experiment is one module, with nothing to list.
"""

import importlib
import pkgutil

from .command import REGISTRY, Command, Output, register

# The plate tests first: the CLI lists its commands in the order they were registered.
for _name in sorted((m.name for m in pkgutil.iter_modules(__path__)), key=lambda n: (n != "plate", n)):
    importlib.import_module(f"{__name__}.{_name}")

__all__ = ["REGISTRY", "Command", "Output", "register"]
