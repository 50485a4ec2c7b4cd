"""The robot and what a measurement device sees of it: URDF loading, KUKA arms, parameter layout, kinematics, measurement models, noise."""
