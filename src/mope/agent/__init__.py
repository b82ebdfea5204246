"""The agent: MoPE and EQL (``agent.py``, built on ``base.py`` and ``agent_state.py``), its networks, losses,
targets, replay buffer and demonstrations, checkpoints, and the training loop with its callbacks (``runner.py``).

``from mope.agent import MoPE`` keeps working: the names of the former module ``mope.agent`` (now
:mod:`mope.agent.agent`) are served from there on first use (:func:`mope.moved.former_module_names`).
"""

from mope.moved import former_module_names

__getattr__ = former_module_names(__name__, "mope.agent.agent")
