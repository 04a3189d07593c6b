"""VDA 5050 vehicles on LIF layouts: order execution, actions, battery, safety field,
messages checked against the official schemas, and the MQTT transport (docs/fleet.md)."""
