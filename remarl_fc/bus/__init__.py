"""The swarm bus: vehicles' states and detections shared between the controllers of a swarm.

`core.SwarmBus` is the protocol; `memory.MemoryBus` (one process, no broker: the embedded
default) and `mqtt.MqttBus` (one process per vehicle over an MQTT broker) implement it with the
same topics, payloads (`schema`) and validation (`core.BusCore`).
"""
