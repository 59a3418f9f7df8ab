"""PLC output over Modbus TCP: the register map of contract section 4, its encoder, the writer
thread beside the real-time loop, and a simulator (a real Modbus TCP server) for commissioning."""
