"""The `refinenet` command line: normals of a user's own cloud with the shipped networks."""
