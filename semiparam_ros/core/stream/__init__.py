"""The message-to-sample stream: messages, pairing, acceleration, rate, glitches and the contact gate."""
