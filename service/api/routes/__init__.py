"""One router per resource; routes validate, delegate and shape the response."""
