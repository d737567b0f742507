"""From a trained run to a robot: the deterministic policy as one network from an observation
to wheel duty cycles (:mod:`.policy`), its ONNX export (:mod:`.export`), camera frames
prepared as in training (:mod:`.frames`), the pilot that turns frames into wheel commands
(:mod:`.pilot`; the policy file's metadata checked with bounds, :mod:`.metadata`) and a ROS 2
node around it (:mod:`.ros_node`)."""
