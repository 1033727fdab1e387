"""The grasp service: a gRPC server (`grasp_service.proto`, its generated `grasp_service_pb2*` modules)
over `GraspDetector`s, and its Python client."""
