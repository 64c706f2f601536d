"""`coloc reproduce`: one module per paper."""
