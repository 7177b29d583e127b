"""The policy layer: observation wrappers (gt_pose / lnet / lnet_no_uncertainty), MaskablePPO pick and drop
skills, and the decision policy that chains them (paper section 4.2). Above ``mor.lnet``; nothing below
imports it."""
