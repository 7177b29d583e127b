"""The localization network (L-Net): poses of the agent and the objects, with calibrated uncertainty, from RGB."""
