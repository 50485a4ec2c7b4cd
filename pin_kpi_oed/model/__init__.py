"""The robot and what a measurement device sees of it: URDF loading, KUKA arms, parameter layout, the batched
kinematics core, measurement models (the device interface and the laser tracker), noise."""
