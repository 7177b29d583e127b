"""The controller for a real robot (and its simulated stand-in): pose source, policy, actuator, bag adapters."""
