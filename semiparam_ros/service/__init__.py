"""The service floor between the learners and the node or the command line.

The learning loop, the served model, feed-forward, checkpoints written off the loop and ``learn``.
"""
