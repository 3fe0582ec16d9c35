"""The experiments: one module each, holding its trial, summary text and command (`command.Command`).

- `plate`: the paper's plate tests, drag and rotate (`PlateTest`, `simulate`)
- `swim`: the two-fin robot swimming (`Swim`, `swim`)
- `user_model`: a user's MJCF model, one joint driven through the medium (`UserModel`; finrft run)
- `intrusion`: a plate pushed down into the medium (`Intrusion`, `intrude`)

`REGISTRY` maps each command name to its `Command`; the CLI gives every entry a subcommand and the tests iterate
it. A new experiment is one module that registers its command (``@register``) and is listed here.
"""

# Importing a module registers its commands, in the order the CLI lists them.
from . import plate  # noqa: F401,I001
from . import swim  # noqa: F401
from . import user_model  # noqa: F401
from . import intrusion  # noqa: F401
from .command import REGISTRY, Command, Output, register

__all__ = ["REGISTRY", "Command", "Output", "intrusion", "plate", "register", "swim", "user_model"]
