"""Read a node's parameters from a ROS 2 parameter YAML file, as `--params-file` would."""

from pathlib import Path
from typing import Optional, Union

import yaml

__all__ = ['IGNORED', 'ParamsError', 'parameter_values']

# parameters every node has that the offline adapters do not use
IGNORED = frozenset({'use_sim_time'})


class ParamsError(ValueError):
    """A parameter file that cannot configure the filter."""


def parameter_values(params_file: Optional[Union[str, Path]], node_name: str,
                     defaults: dict, overrides: Optional[dict] = None) -> dict:
    """
    Return the defaults overridden by the file's section for node_name, then by overrides.

    The section is the first of `node_name`, `/node_name`, `/**/node_name` and `/**` that
    has `ros__parameters`.  Raises ParamsError naming the file and the problem: unreadable,
    no section, or a parameter the node does not have.
    """
    values = dict(defaults)
    if params_file:
        try:
            doc = yaml.safe_load(Path(params_file).read_text()) or {}
        except (OSError, yaml.YAMLError) as exc:
            raise ParamsError(f'{params_file}: cannot read parameters ({exc})') from None
        section = None
        for key in (node_name, '/' + node_name, '/**/' + node_name, '/**'):
            if isinstance(doc.get(key), dict) and 'ros__parameters' in doc[key]:
                section = doc[key]['ros__parameters']
                break
        if section is None:
            raise ParamsError(f'{params_file}: no {node_name}: ros__parameters section')
        unknown = sorted(set(section) - set(values) - IGNORED)
        if unknown:
            raise ParamsError(f'{params_file}: unknown parameter(s) {", ".join(unknown)}')
        values.update({k: v for k, v in section.items() if k not in IGNORED})
    values.update(overrides or {})
    return values
