"""Task kinds: what a mission can ask for, the alternatives of each, their steps and subtrees."""
