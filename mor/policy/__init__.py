"""The policy layer: the variants (``mor.policy.variants``), their observation wrappers, MaskablePPO pick and drop
skills, and the decision policy that chains them (paper section 4.2). Above ``mor.lnet``; nothing below
imports it."""
