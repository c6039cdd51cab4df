"""The boot stage and the firmware update on flash: image slots A/B, boot state, trusted key, update service."""
