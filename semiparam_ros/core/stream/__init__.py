"""The message-to-sample stream: messages, pairing, acceleration, rate, glitches and the contact gate."""

__all__ = [
    "acceleration",
    "episodes",
    "gate",
    "glitch",
    "messages",
    "pipeline",
    "rate",
]
