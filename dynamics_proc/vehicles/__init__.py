"""The machines: the combine on its path, the tractor towing the cart, their integration, Machine Sync, the
ground under their wheels and the field's conditions (docs/field.md)."""
