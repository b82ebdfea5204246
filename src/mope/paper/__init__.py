"""The paper and its neighbours: the two reproductions (``dst.py``: Deep-Sea-Treasure, Fig. 2-3;
``confrontation.py``: the robot game, Fig. 5-6), the benchmark (``benchmark.py``), and the methods it is
measured against: PPO per preference (``ppo.py``) and morl-baselines' Envelope (``envelope.py``)."""
