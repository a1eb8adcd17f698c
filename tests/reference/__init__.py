"""Plain reference implementations that the product's compiled or batched code is tested against."""
