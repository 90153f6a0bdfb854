"""touchdown firmware on an emulated STM32H743 (unicorn): see README.md."""
