"""Peer libraries on crllk's tasks: the lane-keeping task served to a learner in another Python
(:mod:`crllk.peers.env_server`), and the policies such a learner trains, played back in crllk's
own evaluation (:mod:`crllk.rl.peer_policy`, :mod:`crllk.evaluation.peer_runs`)."""
