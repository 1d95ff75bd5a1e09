"""The ROS-free control core: model, synthesis, certificates, delay analysis, simulation."""
