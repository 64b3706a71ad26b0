"""The conditional graph neural network (cGNN): model, data loading, training and evaluation."""
